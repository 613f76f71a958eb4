"""What the lab measures with: dial gauges on magnetic stands, and their slots."""
