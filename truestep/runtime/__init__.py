"""The runtime leaf: processes and their isolation, locks, signals, publishing a folder,
safe reads of handed-over files and escaping for display. It imports nothing of truestep
above it, so every other part may import it."""
