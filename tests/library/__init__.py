"""Device library cross-checks: independent sources transcribed as data."""
