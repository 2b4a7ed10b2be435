"""identify package."""
