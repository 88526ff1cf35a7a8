"""What the SIL vehicle flies: the interface :class:`sim.plant.jsbsim_plant.JSBSimPlant` and
:class:`sim.plant.kinematic_plant.KinematicMavPlant` both give."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from sim.plant.jsbsim_plant import LocalNED, PlantState
    from sim.plant.sitl_turbulence import SitlTurbulence


class Plant(Protocol):
    """A rigid aircraft stepped every ``dt`` (s) by normalized commands (surfaces -1..1, aileron
    > 0 rolls right, elevator > 0 noses down, rudder > 0 yaws right; throttle 0..1); NED about
    ``origin``, FRD body, SI units, radians. ``has_random_wind``: :meth:`set_random_wind` (the
    firmware's SIM_WIND_TURB) is there."""

    dt: float
    origin: LocalNED
    has_random_wind: bool

    @property
    def t(self) -> float: ...
    @property
    def random_wind(self) -> SitlTurbulence | None: ...
    def state(self) -> PlantState: ...
    def step(self, aileron: float, elevator: float, rudder: float, throttle: float) -> None: ...
    def step_rates(
        self, aileron: float, elevator: float, rudder: float, throttle: float
    ) -> tuple[float, float, float, float]:
        """:meth:`step`, then :meth:`rates_airspeed`."""
        ...

    def run(
        self, n: int, aileron: float, elevator: float, rudder: float, throttle: float
    ) -> None: ...
    def rates_airspeed(self) -> tuple[float, float, float, float]:
        """(p, q, r) rad/s FRD and the true airspeed (m/s)."""
        ...

    def attitude_rates(self) -> tuple[float, float, float, float, float, float]:
        """(roll, pitch, yaw) rad and (p, q, r) rad/s."""
        ...

    def set_wind(self, wind_ned_m_s: Any) -> None: ...
    def set_turbulence(self, kind: str = "none", seed: int = 0) -> None: ...
    def set_random_wind(self, turbulence_m_s: float, seed: int = 0) -> None: ...
    def trigger_gust(self, *args: Any, **kw: Any) -> None: ...
