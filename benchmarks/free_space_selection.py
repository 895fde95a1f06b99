"""Choose ``register_multiway``'s free-space limit (``max_violation``) on training scenes.

``benchmarks/rooms_selection.py --setting max_violation``: every fragment of each
chosen 3DMatch scene rebuilt with the defaults and each candidate ``max_violation``
(``none``: no check), scored on the scene's ground-truth pairs. Writes
``free_space_selection.json`` and ``.md`` to ``--output``::

    python benchmarks/free_space_selection.py --scenes redkitchen,hotel1,hotel3,lab_hj
"""

from __future__ import annotations

from rooms_selection import main as select

if __name__ == "__main__":
    raise SystemExit(select(setting="max_violation", stem="free_space_selection"))
