"""One module per screen of the station UI."""
