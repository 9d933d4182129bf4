"""optipose."""
