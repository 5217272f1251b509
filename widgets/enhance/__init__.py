"""The Enhance tab: detail database, the *Enhanced* preview, baking, retiming from a performance."""

from widgets.enhance.panel import EnhancePanel

__all__ = ["EnhancePanel"]
