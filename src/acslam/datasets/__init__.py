"""Readers of public robot datasets, turning their logs into acslam messages.

Ground truth is always returned apart from the messages, so it cannot leak to the server.
"""
