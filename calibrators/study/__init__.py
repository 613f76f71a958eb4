"""Studies: the one agent <-> lab episode loop, the batched comparison of strategies, its
statistics and the engines that spread it over processes."""
