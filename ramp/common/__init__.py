"""Plumbing both sides of MCP need (the backend and its clients), below both in the import
contract: it imports nothing of either."""
