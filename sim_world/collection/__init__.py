"""Data collection: the paper's protocol (goal, sector, test, empty images) and scripted demos."""
