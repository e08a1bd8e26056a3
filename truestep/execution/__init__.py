"""Running: the sweep, the analyses, isolation, the journal, the cluster and the budget."""
