"""The lecture's figures, reproduced from their case files."""
