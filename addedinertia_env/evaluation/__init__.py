"""Floor 5, how an episode is scored, once for every caller (the environment's reward, the
vector env, the benchmark, the trainers, the demo): scoring.py (score_episode: which estimate,
which truth, which metrics). Beside the estimators it calls; reads a record's truth, as
scoring alone may.
"""
