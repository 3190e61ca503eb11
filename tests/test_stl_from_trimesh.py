"""The venv can build a flexure STL the way docs/conventions.md shows: trimesh extrudes a shapely
polygon (its triangulation engine, mapbox-earcut, is a dependency) into a watertight solid."""


def test_extrude_a_hub_spokes_ring_disc(tmp_path):
    import shapely.geometry as g
    import shapely.ops
    import trimesh

    ring = g.Point(0, 0).buffer(30, 64).difference(g.Point(0, 0).buffer(25, 64))
    hub = g.Point(0, 0).buffer(8, 64)
    spokes = [g.box(0, -2, 27, 2)]
    spokes += [shapely.affinity.rotate(spokes[0], a, origin=(0, 0)) for a in (90, 180, 270)]
    profile = shapely.ops.unary_union([ring, hub, *spokes]).difference(g.Point(0, 0).buffer(3, 32))
    solid = trimesh.creation.extrude_polygon(profile, 5.0)
    assert solid.is_watertight and solid.is_volume
    assert abs(solid.volume - profile.area * 5.0) < 1e-6 * solid.volume
    solid.export(tmp_path / "disc.stl")
    assert trimesh.load(tmp_path / "disc.stl").is_watertight
