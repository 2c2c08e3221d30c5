"""Reproductions of the two seed papers (Subedi et al. 2021; Pan, Scott and Ulsoy 1990).

Each paper has one module whose ``run(out_dir, reduced)`` runs what the paper reports and
returns its :class:`~flexctrl.reproduce.items.Section` list, in the paper's order;
:func:`~flexctrl.reproduce.items.write_reproduction` writes ``report.md`` and
``reproduction.json`` from them.
"""
