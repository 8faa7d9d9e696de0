"""Paper methods that are not planners or NLP terms; each module's docstring says which paper it
reproduces (e.g. :mod:`optplan.methods.eba` — the EBA paper: base-attitude restoration of a dual-arm
free-floating robot: BA, EBA, quintic, leader-follower, Fourier near-optimal and optplan's NLP).

Modules are imported on demand (``from optplan.methods import eba``); this package imports nothing
itself.
"""
