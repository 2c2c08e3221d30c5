"""Automatic fidelity: the cheapest model that meets a tip tolerance.

The method is pure: it judges runs handed to it by callables; running scenes for it is
the job of :mod:`flexctrl.scenes.auto` and :mod:`flexctrl.scenes.auto_closed_loop`.

``ladder``            the method, and the names the rest of the toolkit imports;
``rungs``             rungs, bandwidths, tip distances, option checks;
``walk``              the walk over the rungs and the judgement against the reference;
``linear_candidate``  the rung the linear estimates cannot exclude;
``records``           a run made while choosing, the choice, an unreachable tolerance.
"""
