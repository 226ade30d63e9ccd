"""The gain search of ``fjm design`` on a tiny budget, as the search tests run it."""
from fjm_runtime.analysis.search.search import design
from fjm_runtime.analysis.search.settings import SearchSettings

#: A search of 3 draws x 0.3 s, one round, progress silenced: seconds per run once the C step is built.
TINY = dict(draws=3, duration=0.3, screen_draws=3, screen_duration=0.2, rounds=1, max_extra_delay=1, seed=5,
            progress=lambda msg: None)


def run_search(m, progress=None, **settings):
    """``design`` with the settings as keywords (the progress callback apart)."""
    return design(m, SearchSettings(**settings), progress=progress)
