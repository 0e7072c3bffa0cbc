"""Benchmarks: each prints a markdown table and can write JSON. Speed lives here, not in tests."""
