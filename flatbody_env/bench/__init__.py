"""The bench wing: every ``flatbody bench`` measurement, one module per benchmark, on one harness.

:mod:`.harness` times (best of repeats, cases in alternation) and writes each benchmark's JSON, CSV,
PNG and docs block; :mod:`.kernels` holds the compiled kernels only a benchmark runs. The benchmarks measure the layers below and are measured by nothing: only the
command line (and the tests) import this package.
"""
