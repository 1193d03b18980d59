"""Scenes, pure: what a frame contains (people, static geometry, camera, seeds) and the
static meshes (floor, room walls). No GL, Ray or pipeline here."""
