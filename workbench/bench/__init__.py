"""Benchmarks with their baselines: one module per ``workbench bench NAME``."""
