"""Visualisation of flow fields (Middlebury colour coding)."""

from .colorwheel import color_wheel, color_wheel_legend, flow_to_color, flow_to_color_with_legend

__all__ = ["color_wheel", "color_wheel_legend", "flow_to_color", "flow_to_color_with_legend"]
