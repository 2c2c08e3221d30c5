"""Benchmarks behind ``flexctrl bench``: each returns a JSON-ready dict of measured figures."""
