"""Robots and server as separate processes over Zenoh (``acslam serve``, ``acslam robot``,
``acslam run --distributed``)."""
