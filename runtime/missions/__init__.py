"""Missions (§5): behavior composition, HFSM missions and plans, validation, run recording and on-line evaluation."""
