"""roadload.experiments: experiment harnesses (selftests and their test worlds, campaigns, benchmarks)."""
