"""The built-in search methods, one module each; every module here registers itself."""
