"""COLMAP 3.8, in one place each: its database (database.py), its sparse model files (model.py),
running its commands (process.py) and the project folder the live hand-off keeps (project.py)."""
