"""Automatic fidelity: the cheapest model that meets a tip tolerance
(:mod:`flexctrl.fidelity.ladder`).

The method is pure: it judges runs handed to it by callables; running scenes for it is
:mod:`flexctrl.scenes.auto`'s job.
"""
