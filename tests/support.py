"""Paths shared by the tests: the repository and the shipped description files."""

from pathlib import Path

from flexctrl.spec.shipped import data_root

#: The repository (the tests, docs and README live here).
ROOT = Path(__file__).resolve().parents[1]
#: The shipped models, controllers, scenes and studies (package data).
DATA = data_root()
#: The three-link arm of Subedi et al. (2021).
MODEL = DATA / "models" / "subedi3link.toml"
