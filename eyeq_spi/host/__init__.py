"""The Aurix host emulator: bring-up state machine, NVM, scenario sources."""
