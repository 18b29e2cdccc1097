"""safenav benchmarks (not shipped in the wheel; run from a checkout, or as ``safenav bench ...``)."""
