"""Recordings in: WAV files read and checked against the input contract, and what they hold.

Stereo recordings of one path (``recordings``), which channel drives which
(``channels``), DC offsets and clipping (``data_quality``), the corrections a model
carries for its data (``corrections``: clock ratio, excluded stretches) and the
spectral lines the input does not drive (``lines``: hum, engine orders).
"""
