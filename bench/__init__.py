"""Benchmarks: ``python -m bench`` runs every ``bench/bench_*.py``; ``python -m bench NAME`` one.

Each benchmark module exposes ``main() -> int`` and prints its figures as ratios against a
baseline measured in the same run, so the numbers mean the same on any machine.
"""
