"""The hostile cases of benchmarks/hostile_pass.py, one module per class of input, and the runner
that runs and classifies one case."""
