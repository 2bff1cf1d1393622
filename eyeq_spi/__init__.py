"""eyeq-spi: protocol stack, emulator and dissector for the host side of the EyeQ4 SPI link."""

__version__ = "0.1.0"
