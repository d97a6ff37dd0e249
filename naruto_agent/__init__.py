"""The NARUTO agent and its parts: motion planning, mapping, goal search.

Subpackages are imported on demand (``from naruto_agent.planning import plan_path``), so that
importing the package stays cheap and one part can be used without the others.
"""

__all__ = ["planning"]
