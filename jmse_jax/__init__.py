"""jmse_jax: a differentiable JAX merit for computational-imaging lens design.

The JMSE (Stork & Robinson 2008) is the mean-squared error an image keeps after Wiener
restoration; this package evaluates it by quadrature over the sensor band with the OTF
computed only at the quadrature nodes (Berkner & Shroff, "Rethinking sampling topologies for
image quality estimation in Computational Imaging system design").
"""

from . import _requirements  # noqa: F401  (first: checks the dependencies' versions)
from ._aberrations import (
    AbstractAberrations as AbstractAberrations,
    Seidel as Seidel,
    Zernike as Zernike,
    noll_to_nm as noll_to_nm,
    wavefront as wavefront,
)
from ._merit import (
    BALANCED_CANCELLATION as BALANCED_CANCELLATION,
    BALANCED_GRID as BALANCED_GRID,
    CANCELLING_STRENGTH as CANCELLING_STRENGTH,
    CHECKED_CANCELLATION as CHECKED_CANCELLATION,
    CHECKED_SLOPE as CHECKED_SLOPE,
    CHECKED_SNR as CHECKED_SNR,
    CHECKED_SNR_PEAKS as CHECKED_SNR_PEAKS,
    CHECKED_STRENGTH as CHECKED_STRENGTH,
    DEFAULT_TIERS as DEFAULT_TIERS,
    DEGREE_NODES as DEGREE_NODES,
    DEGREE_OVERLAP as DEGREE_OVERLAP,
    DEGREE_SE_NODES as DEGREE_SE_NODES,
    DEGREE_STEEP_SLOPE as DEGREE_STEEP_SLOPE,
    EDGE_TIER_SNR as EDGE_TIER_SNR,
    HIGH_BALANCED_GRID as HIGH_BALANCED_GRID,
    HIGH_DEGREE_NODES as HIGH_DEGREE_NODES,
    HIGH_RAY_GRID as HIGH_RAY_GRID,
    HIGH_STEEP_GRID as HIGH_STEEP_GRID,
    HIGH_STRONG_STRENGTH as HIGH_STRONG_STRENGTH,
    OTF_RADIAL_BY_SNR as OTF_RADIAL_BY_SNR,
    OVERLAP_FLOOR as OVERLAP_FLOOR,
    PRESETS as PRESETS,
    RUN_TIME_CHECKS_VARIABLE as RUN_TIME_CHECKS_VARIABLE,
    SE_ANGULAR_BY_SNR as SE_ANGULAR_BY_SNR,
    STEEP_SLOPE as STEEP_SLOPE,
    WEAK_TIER_SNR as WEAK_TIER_SNR,
    TierShortcut as TierShortcut,
    aberration_strength as aberration_strength,
    baseline_jmse as baseline_jmse,
    jmse as jmse,
    jmse_options as jmse_options,
    otf_radial_for as otf_radial_for,
    run_time_checks as run_time_checks,
    se_angular_for as se_angular_for,
)
from ._numerics import AccuracyWarning as AccuracyWarning
from ._optimise import (
    OptimisationResult as OptimisationResult,
    lens_beyond_checked as lens_beyond_checked,
    lens_merit as lens_merit,
    optimise as optimise,
)
from ._otf import (
    diffraction_limited_otf as diffraction_limited_otf,
    otf as otf,
    otf_fft_grid as otf_fft_grid,
)
from ._pupil import (
    PolarGrid as PolarGrid,
    SquareGrid as SquareGrid,
    sample_opd as sample_opd,
    zernike_fit as zernike_fit,
)
from ._quadrature import (
    QUADRATURES as QUADRATURES,
    frequency_quadrature as frequency_quadrature,
)
from ._simulate import (
    PIXEL_MSE_PER_JMSE as PIXEL_MSE_PER_JMSE,
    MonteCarloResult as MonteCarloResult,
    monte_carlo_mse as monte_carlo_mse,
    predicted_pixel_mse as predicted_pixel_mse,
    random_scene as random_scene,
    restore as restore,
    sensor_frequencies as sensor_frequencies,
    simulate_capture as simulate_capture,
)
from ._spectra import (
    AbstractNoise as AbstractNoise,
    AbstractSignal as AbstractSignal,
    MarkovSignal as MarkovSignal,
    PowerLawSignal as PowerLawSignal,
    WhiteNoise as WhiteNoise,
    WhiteSignal as WhiteSignal,
    error_spectral_density as error_spectral_density,
    wiener_filter as wiener_filter,
)
from ._sweep import (
    SweepResult as SweepResult,
    SweepStatus as SweepStatus,
    beyond_checked as beyond_checked,
    hypercube as hypercube,
    sweep as sweep,
    sweep_jmse as sweep_jmse,
)
from .lens import (
    Lens as Lens,
    Singlet as Singlet,
)

__version__ = "0.1.0"
