"""Many runs: sweeps of algorithms and seeds (local processes or Ray), learning curves read back,
figures and summary tables."""
