"""Lens model: surfaces, paraxial trace, Seidel sums and conversion to waves (SPEC §3.7).

Physical units: mm, 1/mm, degrees, µm. The object is at infinity; the field lies along +y.
"""

from ._designs import (
    PAPER_SINGLET as PAPER_SINGLET,
    paper_singlet as paper_singlet,
)
from ._glass import (
    AIR as AIR,
    FRAUNHOFER_C as FRAUNHOFER_C,
    FRAUNHOFER_D as FRAUNHOFER_D,
    FRAUNHOFER_F as FRAUNHOFER_F,
    N_BK7 as N_BK7,
    AbbeGlass as AbbeGlass,
    AbstractGlass as AbstractGlass,
    CauchyGlass as CauchyGlass,
    ConstantGlass as ConstantGlass,
)
from ._paraxial import (
    LensStatus as LensStatus,
    ParaxialTrace as ParaxialTrace,
    back_focal_length as back_focal_length,
    cutoff_frequency as cutoff_frequency,
    effective_focal_length as effective_focal_length,
    lens_status as lens_status,
    paraxial_trace as paraxial_trace,
    solve_last_curvature as solve_last_curvature,
    validate_lens as validate_lens,
    with_f_number as with_f_number,
    working_f_number as working_f_number,
)
from ._seidel import (
    SeidelSums as SeidelSums,
    defocus_waves as defocus_waves,
    rms_wavefront_error as rms_wavefront_error,
    seidel_sums as seidel_sums,
    seidel_waves as seidel_waves,
    stop_shift as stop_shift,
)
from ._surfaces import (
    Lens as Lens,
    Singlet as Singlet,
    surface_sag as surface_sag,
)
