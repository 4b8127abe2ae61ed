"""``relaxgrip bench``: placeholder until written."""
