"""Synthetic skinned assets for benchmarks (real files that the real readers load)."""
