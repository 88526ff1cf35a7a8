"""`mpf-mavlink certify`: a bound on a mission before it flies (docs/certify.md)."""
