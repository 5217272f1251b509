"""import-linter contracts used by CI (see pyproject.toml [tool.importlinter])."""
