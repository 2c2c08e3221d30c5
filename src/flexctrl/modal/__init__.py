"""Modes of an arm's links: boundary values from the configuration, lookup tables, identification, figures."""
