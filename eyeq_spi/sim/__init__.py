"""The simulated EyeQ: the device side of the SPI interface."""
