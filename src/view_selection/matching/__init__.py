"""Matching the keyframes of a pair: guided by the node's poses (guided.py), in the project's
database (backend.py), with COLMAP's own matcher for the pairs whose poses cannot be trusted."""
