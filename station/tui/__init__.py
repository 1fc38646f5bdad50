"""The station's terminal UI (Textual). Start it with `station` or `station ui`."""
