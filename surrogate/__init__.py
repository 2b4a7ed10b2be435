"""surrogate package."""
