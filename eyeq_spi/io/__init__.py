"""Readers and writers of every file format (see the registry in this package)."""
