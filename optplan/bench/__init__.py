"""Benchmarks (scripts that print figures next to targets; not timed tests)."""
