"""pyclray's benchmarks against Mitsuba 3 and the float64 oracle (run with pytest, see README)."""
