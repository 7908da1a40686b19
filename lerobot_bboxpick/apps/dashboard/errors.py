"""The one error type of the dashboard: a bad request, with the HTTP status the API answers it with."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class RequestError(Exception):
    """A request the dashboard refuses: ``message`` names the field and what is allowed.

    ``status`` is the HTTP status the API answers with: 400 a bad value, 404 something missing
    (a checkpoint, an episode), 409 a request that conflicts with the state (a second run).
    """

    message: str
    status: int = 400
    field: str | None = None

    def __str__(self) -> str:
        return self.message

    def as_json(self) -> dict:
        """The API's error body: ``{"error": message, "field": field}``."""
        return {"error": self.message, "field": self.field}
