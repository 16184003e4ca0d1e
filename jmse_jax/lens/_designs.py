"""The singlet design space of Berkner & Shroff (their Fig. 2), with every open choice fixed.

The paper gives: an F/4.6 singlet, "thickness of surface 1" from 0 to 3 mm, "curvature of
surface 2" from -0.1 to 0.1 1/mm, field 0.95. Read as a Zemax file whose surface 1 is the
aperture stop: surface 1's thickness is the stop-to-lens distance, surface 2 the lens front,
and the back curvature is held by an F-number solve. The choices the paper leaves open are
made here so that the aberrations over the space land in the paper's range (a few waves,
up to about 6 at field 0.95):

- glass N-BK7 (``AbbeGlass(1.5168, 64.17)``), centre thickness 1.5 mm;
- effective focal length 9 mm (entrance-pupil semi-diameter 9 / (2 * 4.6) = 0.978 mm);
- full field 10 degrees; wavelength 587.56 nm (helium d line);
- back curvature solved for working F/4.6 at every point of the space.
"""

from __future__ import annotations

from typing import Any

from ._glass import FRAUNHOFER_D, N_BK7
from ._paraxial import solve_last_curvature
from ._surfaces import Lens, Singlet

__all__ = ["PAPER_SINGLET", "paper_singlet"]

#: The fixed parameters of the paper's singlet space (see the module docstring).
PAPER_SINGLET: dict[str, Any] = dict(
    f_number=4.6,
    focal_length=9.0,
    thickness=1.5,
    field_angle=10.0,
    wavelength=FRAUNHOFER_D,
    stop_distance_range=(0.0, 3.0),
    front_curvature_range=(-0.1, 0.1),
    field=0.95,
)


def paper_singlet(stop_distance=1.0, front_curvature=0.0, *, image_shift=0.0,
                  glass=N_BK7) -> Lens:
    """A point of the paper's F/4.6 singlet space (back curvature from the F-number solve).

    Parameters
    ----------
    stop_distance : float in [0, 3] [mm], stop to front vertex ("thickness of surface 1")
    front_curvature : float in [-0.1, 0.1] [1/mm] ("curvature of surface 2")
    image_shift : float [mm], image plane from the paraxial focus, + away from the lens
    glass : glass model, default N-BK7

    Returns
    -------
    Lens (float leaves: usable under ``vmap``/``grad``)
    """
    p = PAPER_SINGLET
    lens = Singlet(
        front_curvature, 0.0, p["thickness"], glass, stop_distance=stop_distance,
        ep_radius=p["focal_length"] / (2.0 * p["f_number"]), field_angle=p["field_angle"],
        wavelength=p["wavelength"], image_shift=image_shift,
    )
    return solve_last_curvature(lens, p["f_number"])
