"""Applications built on the library: the main job, the canary, the demo, the benchmarks and the CLI."""
