"""crashdem: coupled DEM soil + Exudyn multibody crash toolkit."""
from crashdem.signal import G0, Signal

__version__ = "0.1.0"
__all__ = ["G0", "Signal", "__version__"]
