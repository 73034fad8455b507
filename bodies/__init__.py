"""bodies package."""
