"""The paper's own studies (Lubricants 2019, 7(8), 64): section 3 (Duffing) and section 4 (the rig's experiments)."""
