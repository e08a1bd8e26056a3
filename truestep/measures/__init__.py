"""What a run is measured by: errors, energy, properties, stability, restitution, picks."""
