"""Replays of real recordings: CARMEN laser logs and the UTIAS MRCLAM multi-robot data,
run through the SLAM and mapping stages and scored against what the recording provides."""
