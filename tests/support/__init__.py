"""Shared test helpers: independent references and numeric utilities (no tests here)."""
