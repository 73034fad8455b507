import os

# Numba compilation is cached on disk next to the sources (cache=True); keep it there so a
# second pytest run on the same checkout pays no compile time.
os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(os.path.dirname(__file__), "..", ".numba_cache"))
