"""soil package."""
