"""SPI captures: pcapng files with one interface per SPI channel (see specs/capture.yaml)."""
