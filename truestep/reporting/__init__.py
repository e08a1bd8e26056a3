"""The report: its pages, tables, figures and how it is published."""
