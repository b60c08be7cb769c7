"""thermcap API: a FastAPI service that indexes archived sessions and serves them (``create_app``)."""
