"""Controller design: gain limits, PD/PID placement, stability maps.

Modules: :mod:`.limits` (Hurwitz / PCT / exact sampled-data gain limits, margins,
PD zero placement) and :mod:`.stability` (parameter-sweep stability maps).
"""
