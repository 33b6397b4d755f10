"""The seed's identified models (appendix A) used as true plants of synthetic sessions.

Matrices as printed in the thesis, section A.1 (feedback: headphone voltage -> ear
microphone, n = 7) and A.2 (feed-forward: chin microphone -> ear microphone, n = 5),
at fs = 44.1 kHz. Both are stable. The printed FB transfer-function polynomial is not
reproduced: rounded to four digits it has poles at |z| = 1.26.
"""

from __future__ import annotations


from .model import Model

__all__ = ["APPENDIX_A_FS", "appendix_a_model"]

APPENDIX_A_FS = 44100.0

_FB = dict(
    A=[
        [0.9916, -0.3021, -0.01446, -0.3975, 0.3342, 0.8979, -1.751],
        [1.014e-5, 0.9818, 0.5898, 0.189, -0.9155, -1.135, 2.958],
        [-0.0006971, -0.02378, 0.868, 0.8622, -0.4149, -1.494, 2.669],
        [0.0001233, 0.002188, -0.1101, 0.8439, -1.218, -0.9761, 2.992],
        [0.0001113, 0.001061, 0.007756, 0.1362, 0.8197, 1.692, -2.22],
        [9.924e-6, 0.0001823, 0.004315, -0.009561, -0.08712, 0.8108, -2.475],
        [4.181e-7, -1.143e-5, -2.112e-5, 0.0001056, 0.0008508, 0.02776, 1.011],
    ],
    B=[[-0.7629], [0.3258], [-0.0828], [-0.01179], [0.004377], [-0.00065], [-0.0001813]],
    C=[[0.3142, 0.472, -0.509, 0.4186, 0.3623, -0.2782, -0.1635]],
    D=[[0.0]],
)

_FF = dict(
    A=[
        [0.9752, 0.3421, -0.07598, -0.6669, 0.8977],
        [-0.01128, 0.9184, -0.8166, -0.5002, 1.722],
        [0.000338, 0.1704, 0.8682, 1.292, -1.428],
        [0.001693, -0.004514, -0.1086, 0.8146, -2.106],
        [-2.869e-5, -0.000823, -0.002818, 0.0492, 0.9329],
    ],
    B=[[0.04258], [-0.0002361], [-0.0002576], [0.0002576], [0.000179]],
    C=[[0.3763, -0.4799, -0.4982, 0.4897, 0.323]],
    D=[[0.0]],
)


def appendix_a_model(path: str) -> Model:
    """The seed's appendix-A model of path 'fb' or 'ff' as a Model at 44.1 kHz."""
    matrices = {"fb": _FB, "ff": _FF}.get(path)
    if matrices is None:
        raise ValueError(f"path must be 'fb' or 'ff'; found {path!r}")
    return Model(path=path, fs=APPENDIX_A_FS, identification={"source": "seed appendix A"}, **matrices)
