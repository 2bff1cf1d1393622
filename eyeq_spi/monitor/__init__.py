"""``eyeq-spi monitor``: a live terminal view. :mod:`.sources` advance the protocol and make a
:class:`.model.Snapshot`, :mod:`.view` draws it with rich, :mod:`.app` alternates the two at
``--refresh`` Hz."""
