"""The recorder's benchmarks, each against an anchor measured in the same run: record, analysis, imports."""
