"""HDF5 session recordings: schema, crash-safe writer, checked reader."""
