"""Gates, the baseline compare and the CI outputs (JUnit, Markdown, JSON)."""
