"""Pictures of captures (``eyeq-spi plot``): the bird's-eye scene, stream timing and link
behaviour, read through the dissector; matplotlib (the ``plot`` extra) is imported only when
drawing."""
