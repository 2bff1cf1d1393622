"""Wireshark support: a Lua dissector generated from ``specs/`` (:func:`generate_lua`)."""

from eyeq_spi.wireshark.lua_gen import generate_lua

__all__ = ["generate_lua"]
