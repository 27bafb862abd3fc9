"""Shipping a design: the versioned, hashed gain artifact (``gains.json``, its schema and invariants), its
python-control views, and the C rendered from it."""
