"""Serial laser interferometer: line protocol and client."""
