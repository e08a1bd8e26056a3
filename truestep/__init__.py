"""truestep: the harness (CLI, runner, metrics, stability search, gates, reports)."""
