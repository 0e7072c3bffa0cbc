"""The recording opens on what the run used: hazcams and the goodness map for autonav, the VO camera
and slip series for VO runs, no VO series without VO; `rover-sim view` prints a web URL on a headless machine."""

from __future__ import annotations

from rover_sim.cli.view import web_url
from rover_sim.io.blueprint import RunLayout, blueprint_for, view_names
from rover_sim.runtime.run import layout_of
from rover_sim.scenario.loading import load_scenario


def test_spirit_autonav_opens_on_the_goodness_map_and_hazcams():
    layout = layout_of(load_scenario("spirit_autonav"))
    assert layout.autonav and layout.vo_camera is None
    names = view_names(blueprint_for(layout))
    first_tab = names[1:4]  # after the 3D world view: the first camera tab group
    assert first_tab == ["GESTALT goodness (top-down)", "hazcam front left", "hazcam front depth"]
    assert not any("navcam" in n for n in names), names
    assert "slip per VO step" not in names and "VO inliers" not in names


def test_vo_run_opens_on_its_vo_camera_with_slip_series():
    names = view_names(blueprint_for(layout_of(load_scenario("wopmay"))))
    assert names[1:3] == ["navcam left", "navcam depth"]
    assert "slip per VO step" in names and "GESTALT goodness (top-down)" not in names


def test_hazcam_vo_run_has_no_empty_navcam_view():
    names = view_names(blueprint_for(RunLayout(vo_camera="hazcam_front")))
    assert not any("navcam" in n for n in names)


def test_web_url_points_the_viewer_at_the_local_proxy():
    # 127.0.0.1, not "localhost" (which a browser may try as ::1 first): the servers listen on IPv4 127.0.0.1
    assert web_url(9090) == "http://127.0.0.1:9090/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A9876%2Fproxy"
    assert web_url(9090, 9876, "0.0.0.0").startswith("http://127.0.0.1:9090/")  # every interface: this one too


def test_a_run_without_vo_records_no_vo_series(tmp_path):
    from test_runner import TINY  # pytest puts this folder on sys.path

    from rover_sim.io.rrd import entity_row_counts
    from rover_sim.runtime.run import run_scenario
    from rover_sim.scenario.loading import scenario_from_dict

    sc = scenario_from_dict(TINY, overrides=["nav.vo=false", "commands.0.distance_m=0.3"])
    run_scenario(sc, tmp_path, record=True)
    entities = set(entity_row_counts(tmp_path / "recording.rrd"))
    assert "/plots/position_error_m/dead_reckoning" in entities
    plots = sorted(e for e in entities if e.startswith("/plots"))
    assert not any(e.endswith("/vo") or e.startswith(("/plots/slip_pct", "/plots/vo_inliers")) for e in plots), plots
