"""Pictures of captures: the bird's-eye scene, stream timing and link behaviour
(``eyeq-spi plot``).

Everything is read through the dissector engine (:mod:`eyeq_spi.dissect.engine`), so decoded
objects, lane polynomials, signs, timing and link events come from the same code as
``eyeq-spi dissect``. :mod:`.scene` turns decoded fields into plain objects, lines and signs and
needs no plotting library; matplotlib (the ``plot`` extra) is imported only when drawing.
"""

