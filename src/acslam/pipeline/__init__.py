"""The server's pipeline: stage interfaces, the plugin registry, the snapshot, the server.

:mod:`~acslam.pipeline.stages` says what each stage must do, :mod:`~acslam.pipeline.registry`
maps the names a scenario uses to the classes that do it, and
:mod:`~acslam.pipeline.server` runs the stages in the order of thesis Fig. 4.2. What the
server has decided after a step leaves it only as a :class:`~acslam.pipeline.snapshot.Snapshot`.
"""
