"""Benchmark tools: generated scenes and the drivers of ``make bench-throughput``."""
