"""Closed-loop evaluation of policies in the lego_pick simulator."""
