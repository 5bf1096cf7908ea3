"""The names, records and file handling every layer shares: the frames, orders and tally of the
public contract (docs/conventions.md), the table's layout and its noise statistics, config choices,
atomic writes and stop signals. No numba, no tracer: the lowest layer."""
