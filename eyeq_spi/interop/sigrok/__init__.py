"""The ``eyeq_spi`` protocol decoder for libsigrokdecode, shipped as files: ``eyeq-spi
sigrok-decoder --install DIR`` copies the ``eyeq_spi`` folder beside this file to DIR."""
