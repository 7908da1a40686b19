"""The scene the dashboard tests load, shared by the API and browser tests."""

SETTING, SEED = "grid_id", 3
