"""Recordings in: WAV files read and checked against the input contract, and what they hold.

Stereo recordings of one path (``recordings``: the types, opening, the contract's
checks) decoded from any PCM or float WAV (``wav``), Welch spectra from a
``read(start, stop)`` callable (``welch``: a file in blocks or an array alike), the
checks that the ear channel follows the input (``ear_channel``) and which channel
drives which (``channels``), DC offsets and clipping (``data_quality``, ``clipping``:
clipped stretches, also below full scale), the corrections a model carries for its
data (``corrections``: clock ratio, excluded stretches) and the spectral lines the
input does not drive (``lines``: hum, engine orders).
"""
