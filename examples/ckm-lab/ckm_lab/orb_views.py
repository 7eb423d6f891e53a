"""The lab's ORB views (``lab_objects_orb_views.txt``, D175), learnt by the general trainer.

:mod:`plugins.sim.orb_training` renders each textured object of a system's environment from all
round it; the lab trains its model file on its own environment (``lab.xml``) as its Turtlebot's
simulated Xtion sees it (577.3 px at 640 columns, resources.xml ``cameras``). Run after changing
the lab's textures, skins or environment::

    nice -n 19 .venv/bin/python -m ckm_lab.orb_views
"""

from __future__ import annotations

from collections.abc import Sequence

from plugins.sim import orb_training

from . import CONFIGS, MODELS

XTION_FOCAL = 577.3
"""The simulated Xtion's focal length at 640 columns (resources.xml ``cameras``), pixels."""
COMMAND = "nice -n 19 .venv/bin/python -m ckm_lab.orb_views"


def arguments() -> list[str]:
    """The trainer's command line for the lab's model file, system and camera."""
    return ["--model", str(MODELS / "lab_objects_orb.yml"), "--system", str(CONFIGS / "lab.xml"),
            "--focal", str(XTION_FOCAL)]


def main(argv: Sequence[str] | None = None) -> int:
    """Train the lab's views (``argv`` adds to or overrides the lab's arguments)."""
    return orb_training.main([*arguments(), *(argv or [])], written_by=COMMAND)


if __name__ == "__main__":
    raise SystemExit(main())
