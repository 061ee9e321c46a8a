"""Benchmarks behind `kinema bench ...` (printed tables; targets live here, not in timed tests)."""
