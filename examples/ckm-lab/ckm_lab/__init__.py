"""The thesis' two-robot lab (Turtlebot + Nao, §7.1) on CKM: what is truly the lab's and no one else's.

- :mod:`.scenes`: synthetic RGB frames of the lab objects (the Xtion's stream of §7.4.1).
- :mod:`.shapes`: a synthetic depth camera (the lab's Asus Xtion) and the lab's interaction objects.
- :mod:`.shape_training`: the generator of the lab's trained shape model (``lab_objects_shapes.pcd``).
- :mod:`.orb_views`: the lab's ORB views (``lab_objects_orb_views.txt``) learnt by the general trainer.
- :mod:`.table_7_9`: the thesis' Table 7.9, registered as a reference table of the run report.

The lab's configuration (its system, missions, environment and model files) stays data in the
checkout's ``configs/usecase`` (:data:`CONFIGS`, D272). The general packages (``ckmconf``,
``runtime``, ``plugins``, ``editor``) never import this package (tests/test_lab_boundary.py).
"""

from __future__ import annotations

from pathlib import Path

CONFIGS = Path(__file__).resolve().parents[3] / "configs" / "usecase"
"""The lab's configuration in the checkout this package is installed from (editable, as setup.sh does)."""
MODELS = CONFIGS / "models"
"""The lab's trained models and model files."""
