"""Modes of an arm's links: boundary values, lookup tables, identification, figures."""
