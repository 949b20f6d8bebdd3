"""The installed tools' main() functions; scripts/<tool> calls them (rosrun finds the script)."""
