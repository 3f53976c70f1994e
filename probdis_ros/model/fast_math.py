# Copyright 2026 probdis_ros contributors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Fast, exact-enough math for the compiled kernels: inlined, branch-free, vectorisable."""

import math

import numba
import numpy as np

# asin(z) = z + z^3 g(z^2) on [0, 1/2]: g fitted to its Taylor series (Chebyshev nodes,
# degree 12); within 1 ulp of libm's asin there, so arccos is within 2 ulp of libm's acos.
_G0, _G1, _G2, _G3 = (0.16666666666666652, 0.07499999999999062, 0.044642857145245546,
                      0.030381944220602152)
_G4, _G5, _G6, _G7 = (0.02237216971363298, 0.017352468476557165, 0.013970082058240421,
                      0.011490299128017144)
_G8, _G9, _G10, _G11, _G12 = (0.010249877585098172, 0.005773215955924502,
                              0.01653494841483269, -0.013488560155481588,
                              0.027819480814899197)


@numba.njit(cache=True, inline='always')
def arccos(x):
    """
    Return the arc cosine of x in [-1, 1], inlined and branch-free (loops vectorise).

    |x| <= 1/2: pi/2 - asin(x); beyond: 2 asin(sqrt((1 - |x|) / 2)), reflected for x < 0.
    """
    a = abs(x)
    big = a > 0.5
    z = np.sqrt((1.0 - a) * 0.5) if big else a
    t = z * z
    g = (_G0 + t * (_G1 + t * (_G2 + t * (_G3 + t * (_G4 + t * (_G5 + t * (_G6 + t * (
        _G7 + t * (_G8 + t * (_G9 + t * (_G10 + t * (_G11 + t * _G12))))))))))))
    r = z + z * t * g
    small = 0.5 * np.pi - r if x >= 0.0 else 0.5 * np.pi + r
    large = 2.0 * r if x >= 0.0 else np.pi - 2.0 * r
    return large if big else small


@numba.njit(cache=True, inline='always')
def rotation_angle(trace):
    """Return the angle in [0, pi] of a rotation from its trace, as the kernel's D_ORIENT."""
    return 2.0 * arccos(np.sqrt(min(1.0, max(0.0, (trace + 1.0) * 0.25))))


# sin r = r + r^3 s(r^2) and cos r = 1 - r^2 / 2 + r^4 c(r^2) on |r| <= pi/4: Taylor series
# to r^17 and r^18 (the next terms are below 1e-19); pi/2 in two parts, the first of 33
# bits so that k * _HALF_PI_HI is exact (Cody and Waite's reduction)
_S0, _S1, _S2, _S3, _S4, _S5, _S6 = ((-1) ** (k + 1) / math.factorial(2 * k + 3)
                                     for k in range(7))
_C0, _C1, _C2, _C3, _C4, _C5, _C6 = ((-1) ** k / math.factorial(2 * k + 4) for k in range(7))
_HALF_PI_HI = 1.5707963267341256
_HALF_PI_LO = 6.077100506506192e-11


@numba.njit(cache=True, error_model='numpy', inline='always')
def sincos(x):
    """
    Return (sin x, cos x), within 2 ulp (1e-16 absolute) of libm's for |x| up to a few turns.

    Without branches, so that loops of it vectorise: about 1 ns a pair in a loop against
    libm's 14 (one reduction by the nearest multiple k of pi/2, two polynomials, and the
    quadrant of k choosing which is the sine and its sign).  For work whose outcome does
    not hinge on the last bit.
    """
    k = np.round(x * (2.0 / np.pi))
    r = (x - k * _HALF_PI_HI) - k * _HALF_PI_LO
    t = r * r
    s = r + r * t * (_S0 + t * (_S1 + t * (_S2 + t * (_S3 + t * (_S4 + t * (_S5 + t * _S6))))))
    c = 1.0 - 0.5 * t + t * t * (_C0 + t * (_C1 + t * (_C2 + t * (_C3 + t * (_C4 + t * (
        _C5 + t * _C6))))))
    odd = k * 0.5 != np.floor(k * 0.5)           # sin x = +-cos r, cos x = -+sin r
    quadrant = k - 4.0 * np.floor(k * 0.25)      # k mod 4
    sin_r = c if odd else s
    cos_r = s if odd else c
    return (-sin_r if quadrant >= 2.0 else sin_r,
            -cos_r if (quadrant == 1.0 or quadrant == 2.0) else cos_r)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def sincos_into(x, sin_out, cos_out):
    """Write the :func:`sincos` of each element of x (1-D) to sin_out and cos_out."""
    for i in range(x.shape[0]):
        sin_out[i], cos_out[i] = sincos(x[i])
