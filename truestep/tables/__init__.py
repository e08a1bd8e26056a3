"""The tables' columns (one spec) and their readers."""
