"""sitl."""
