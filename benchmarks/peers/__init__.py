"""Peer-code runners (DustPy, PySDM) used by the benchmark scripts; optional extra `peers`."""
