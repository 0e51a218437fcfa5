"""Stability of the sampled position loop: gain limits and parameter-sweep maps.

:mod:`.limits` gives the continuous Hurwitz, PCT and exact sampled-data gain limits
and the margins; :mod:`.maps` sweeps two parameters into a stability map.
"""
