"""The HTTP routes, one module per resource; each guards itself with a scope (security.require)."""
