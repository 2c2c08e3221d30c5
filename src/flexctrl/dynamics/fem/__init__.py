"""Floating-frame finite-element models (Pan, Scott & Ulsoy 1990)."""
