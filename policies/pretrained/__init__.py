"""Pre-trained policies shipped with dronewpt (package data: model zip + metadata JSON)."""
