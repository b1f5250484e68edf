"""The optimiser's options, declared once in ``service.options``: every option walked through every
layer (the ``render-budget optimize`` CLI, the REST job request, the add-on's properties, the batch
``optimize`` arguments and the run configuration) with the same defaults, bounds and choices."""

from __future__ import annotations

import argparse
import math

import pytest

from service import options
from service.api.schemas import JobCreate, JobOptionsIn
from service.cli import build_parser
from service.optimize import OptimizeConfig

PUBLIC = options.PUBLIC


def _parse_cli(*extra: str) -> argparse.Namespace:
    return build_parser().parse_args(["optimize", "scene.glb", "--path", "p.json", "--out", "s.json", *extra])


def _parse_batch(*extra: str) -> argparse.Namespace:
    from addon import batch

    return batch.parser().parse_args(["optimize", *extra])


def _inside(opt: options.Option) -> list[str]:
    """Text values at the bounds and the default (what every layer must accept)."""
    if opt.choices:
        return list(opt.choices)
    fmt = (lambda v: str(int(v))) if opt.kind is int else repr
    return [fmt(opt.minimum), fmt(opt.maximum)] + ([] if opt.default is None else [fmt(opt.default)])


def _outside(opt: options.Option) -> list[str]:
    """Text values every layer must refuse."""
    if opt.choices:
        return ["no-such-choice"]
    if opt.kind is int:
        return [str(int(opt.minimum) - 1), str(int(opt.maximum) + 1)]
    return [repr(opt.minimum / 2 if opt.minimum > 0 else opt.minimum - 1), repr(opt.maximum * 2), "nan"]


def _value(opt: options.Option, text: str) -> object:
    return text if opt.kind is str else opt.kind(float(text))


def test_schema_defaults_are_valid_and_described() -> None:
    assert options.check(options.defaults()) == options.defaults()
    for opt in options.OPTIONS:
        assert opt.help and opt.label and opt.kind in (bool, int, float, str)
        if opt.kind in (int, float) and opt.public:
            assert opt.minimum is not None and opt.maximum is not None, opt.name
    with pytest.raises(ValueError, match="unknown"):
        options.check({"no_such_option": 1})
    with pytest.raises(ValueError, match="min_depth"):
        options.check({"min_depth": 5, "max_depth": 4})
    assert options.eval_resolution(None, 36, 16 / 9) == (64, 36)
    assert options.eval_resolution(50, 40, 16 / 9) == (50, 40)
    assert options.only_overrides({"seed": 0, "population": 30}) == {"population": 30}


@pytest.mark.parametrize("opt", PUBLIC, ids=lambda o: o.name)
def test_cli_takes_each_option_with_the_schema_default_and_bounds(opt: options.Option) -> None:
    assert getattr(_parse_cli(), opt.name) == opt.default
    for text in _inside(opt):
        assert getattr(_parse_cli(opt.cli_flag, text), opt.name) == _value(opt, text)
    for text in _outside(opt):
        with pytest.raises(SystemExit):
            _parse_cli(opt.cli_flag, text)


@pytest.mark.parametrize("opt", PUBLIC, ids=lambda o: o.name)
def test_batch_optimize_takes_each_option_as_an_override_with_the_same_bounds(opt: options.Option) -> None:
    assert getattr(_parse_batch(), opt.name) is None  # not given: the .blend's value stays
    for text in _inside(opt):
        assert getattr(_parse_batch(opt.cli_flag, text), opt.name) == getattr(
            _parse_cli(opt.cli_flag, text), opt.name)
    for text in _outside(opt):
        with pytest.raises(SystemExit):
            _parse_batch(opt.cli_flag, text)


@pytest.mark.parametrize("opt", PUBLIC, ids=lambda o: o.name)
def test_rest_job_request_has_the_schema_default_and_bounds(opt: options.Option) -> None:
    prop = JobOptionsIn.model_json_schema()["properties"][opt.name]
    assert prop["default"] == opt.default and prop["description"] == opt.help
    if opt.choices:
        assert tuple(prop["enum"]) == opt.choices
    elif opt.kind in (int, float):
        number = next(p for p in prop.get("anyOf", [prop]) if p.get("type") in ("integer", "number"))
        assert (number["minimum"], number["maximum"]) == (opt.minimum, opt.maximum)
    for text in _inside(opt):
        partner = {"max_depth": 8} if opt.name == "min_depth" else {}  # min_depth <= max_depth
        got = JobOptionsIn(**{opt.name: _value(opt, text)}, **partner)
        assert getattr(got, opt.name) == _value(opt, text)
    for text in _outside(opt):
        with pytest.raises(ValueError):
            JobOptionsIn(**{opt.name: text if opt.kind is str else float(text)})


def test_public_and_internal_options_reach_the_run_configuration() -> None:
    config = OptimizeConfig()
    for opt in options.OPTIONS:
        assert getattr(config, opt.name) == opt.default
    assert set(JobOptionsIn.model_fields) == {o.name for o in PUBLIC}
    with pytest.raises(ValueError, match="max_depth"):
        OptimizeConfig(max_depth=9)
    with pytest.raises(TypeError):
        OptimizeConfig(6)  # keyword only


def test_a_job_request_stores_every_option_and_reads_older_spellings() -> None:
    from service.jobs import LEGACY_SPEC_DEFAULTS, spec_options

    path = {"version": 1, "fps": 30.0, "frames": [{"time": 0.0, "matrix_world": [
        [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "vfov": 0.7, "resolution": [64, 48]}]}
    body = JobCreate(scene_id="a" * 64, camera_path=path, options={"population": 30})
    spec = body.model_dump(mode="json", exclude_none=True)
    every = {o.name: o.default for o in PUBLIC if o.default is not None}
    assert spec["options"] == {**every, "population": 30}
    assert "thresholds" not in spec and "resolution" not in spec
    assert spec_options(spec)["population"] == 30
    old = JobCreate(scene_id="a" * 64, camera_path=path, thresholds={"power_w": 0.2}, resolution=(32, 24))
    got = old.options.model_dump()
    assert (got["threshold_power_w"], got["eval_width"], got["eval_height"]) == (0.2, 32, 24)
    with pytest.raises(ValueError, match="disagrees"):
        JobCreate(scene_id="a" * 64, camera_path=path, thresholds={"error": 0.2},
                  options={"threshold_error": 0.3})
    # a request stored by an earlier version (thresholds and resolution apart, fewer options)
    stored = {"thresholds": {"power_w": 0.1, "error": 0.02}, "resolution": [64, 48],
              "options": {"max_depth": 2, "population": 8, "generations": 3, "seed": 1,
                          "exhaustive_limit": 9}}
    values = spec_options(stored)
    assert values["view_sampling"] == LEGACY_SPEC_DEFAULTS["view_sampling"] == "aimed"
    assert (values["eval_width"], values["eval_height"], values["threshold_error"]) == (64, 48, 0.02)


# -- the add-on's scene properties (real bpy) -------------------------------------------------------------
@pytest.fixture(scope="module")
def scene_props(tmp_path_factory: pytest.TempPathFactory):
    bpy = pytest.importorskip("bpy")
    from tests.addon_support import disable_dev, enable_dev, stage_extension

    enable_dev(bpy, stage_extension(tmp_path_factory.mktemp("ext")))
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    yield bpy.context.scene.render_budget
    disable_dev()


@pytest.mark.blender
def test_addon_properties_have_the_schema_default_and_bounds(scene_props) -> None:
    import importlib

    from tests.addon_support import EXT_MODULE

    properties = importlib.import_module(f"{EXT_MODULE}.properties")
    rna = scene_props.bl_rna.properties
    values = properties.option_values(scene_props)
    for opt in PUBLIC:
        prop = rna[opt.name]
        assert values[opt.name] == opt.default, opt.name  # 0.05 read back as 0.05, 0 as None
        assert prop.description.lower().startswith(opt.help.lower())
        if opt.choices:
            assert tuple(item.identifier for item in prop.enum_items) == opt.choices
            continue
        lo = 0 if opt.optional else opt.minimum  # 0 stands for None
        assert math.isclose(prop.hard_min, lo, rel_tol=1e-6) and math.isclose(prop.hard_max, opt.maximum,
                                                                                rel_tol=1e-6), opt.name
        for text in _outside(opt):
            with pytest.raises(ValueError):
                properties.set_option(scene_props, opt.name, _value(opt, text))
    properties.set_option(scene_props, "eval_width", None)
    assert scene_props.eval_width == 0 and properties.option_values(scene_props)["eval_width"] is None
    properties.set_option(scene_props, "threshold_error", 0.003)
    assert properties.option_values(scene_props)["threshold_error"] == 0.003
    panels = importlib.import_module(f"{EXT_MODULE}.panels")
    import inspect

    assert "option_schema.PUBLIC" in inspect.getsource(panels.draw_options)


# -- the store lookup's query options (frame-rate target, priority) ----------------------------------------
QUERY = options.QUERY_OPTIONS
_LOOKUP = ["--position", "0", "0", "0", "--direction", "0", "1", "0", "--error-budget", "0.02"]
_VERIFY = ["--scene", "s.rbscene", "--path", "p.json", "--error-budget", "0.02"]


def _batch_parse(batch, command: str, *extra: str):
    return lambda *a: batch.parser().parse_args([command, *extra, *a])


def _query_command_lines() -> dict[str, tuple]:
    """Every command line that looks a store up: (parse(*extra), what it reads when the option is not
    given: the schema default, or None where an unset option leaves the .blend's value)."""
    from addon import batch
    from tools import demo

    return {
        "query": (lambda *a: build_parser().parse_args(["query", "s.json", *_LOOKUP, *a]), "default"),
        "verify": (lambda *a: build_parser().parse_args(["verify", "s.json", *_VERIFY, *a]), "default"),
        "demo": (lambda *a: demo.parser().parse_args(list(a)), "default"),
        **{f"batch {cmd}": (_batch_parse(batch, cmd, *extra), None)
           for cmd, extra in (("evaluate", ["--out", "r"]), ("playback", []), ("optimize", []))},
    }


@pytest.mark.parametrize("opt", QUERY, ids=lambda o: o.name)
def test_every_command_line_that_looks_a_store_up_takes_each_query_option(opt: options.Option) -> None:
    for name, (parse, unset) in _query_command_lines().items():
        assert getattr(parse(), opt.name) == (opt.default if unset else None), name
        for text in _inside(opt):
            assert getattr(parse(opt.cli_flag, text), opt.name) == _value(opt, text), name
        for text in _outside(opt):
            with pytest.raises(SystemExit):
                parse(opt.cli_flag, text)


def test_fps_store_names_the_stores_own_frame_rate_on_every_command_line() -> None:
    """``--fps store``: where leaving --fps out means the store's own rate (query, verify, demo) it is the
    same as leaving it out; in batch, where leaving it out keeps the .blend's value, it is the marker that
    sets that value back (``options.DERIVE``). The usage and help say so; other words are refused."""
    for name, (parse, unset) in _query_command_lines().items():
        assert parse("--fps", "store").fps is (options.DERIVE if unset is None else None), name
        for text in ("Store", "stores", "derive"):
            with pytest.raises(SystemExit):
                parse("--fps", text)
    for with_default, says in ((True, "store: that default, as when left out"),
                               (False, "left out: the value set earlier stays; store: back to that default")):
        ap = argparse.ArgumentParser()
        options.add_argument(ap, options.QUERY_FPS, with_default=with_default)
        text = " ".join(ap.format_help().split())
        assert "--fps FPS|store" in text and says in text, text
    assert options.from_arguments(argparse.Namespace(eval_width=options.DERIVE)) == {"eval_width": None}
    assert all(o.optional for o in (*options.OPTIONS, *QUERY) if o.derived_word)  # a word for None only


@pytest.mark.parametrize("opt", QUERY, ids=lambda o: o.name)
def test_rest_query_and_verify_requests_take_each_query_option(opt: options.Option) -> None:
    from service.api.schemas import StoreQuery, VerifyRequest

    path = {"version": 1, "fps": 30.0, "frames": [{"time": 0.0, "matrix_world": [
        [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "vfov": 0.7, "resolution": [64, 48]}]}
    bodies = {StoreQuery: {"position": [0, 0, 0], "direction": [0, 1, 0], "error_budget": 0.02},
              VerifyRequest: {"camera_path": path, "error_budget": 0.02}}
    for model, body in bodies.items():
        prop = model.model_json_schema()["properties"][opt.name]
        assert prop.get("default") == opt.default and prop["description"] == opt.help
        if opt.choices:
            assert tuple(prop["enum"]) == opt.choices
        else:
            number = next(p for p in prop.get("anyOf", [prop]) if p.get("type") == "number")
            assert (number["minimum"], number["maximum"]) == (opt.minimum, opt.maximum)
        assert getattr(model(**body), opt.name) == opt.default  # an older request without the field
        for text in _inside(opt):
            assert getattr(model(**body, **{opt.name: _value(opt, text)}), opt.name) == _value(opt, text)
        for text in _outside(opt):
            with pytest.raises(ValueError, match=opt.name):
                model(**body, **{opt.name: text if opt.kind is str else float(text)})


def test_query_options_are_checked_together_and_sent_only_when_changed() -> None:
    assert options.check_query({}) == {"fps": None, "priority": "frame_rate", "error_margin": 0.0,
                                       "power_margin": 0.0}
    assert options.check_query({"priority": "budget", "fps": 12}) == {
        "fps": 12.0, "priority": "budget", "error_margin": 0.0, "power_margin": 0.0}
    with pytest.raises(ValueError, match="error_margin must be in"):
        options.check_query({"error_margin": -0.001})
    with pytest.raises(ValueError, match="power_margin must be in"):
        options.check_query({"power_margin": 0.6})
    with pytest.raises(ValueError, match="priority must be one of frame_rate, budget"):
        options.check_query({"priority": "speed"})
    with pytest.raises(ValueError, match="unknown query options"):
        options.check_query({"frame_rate": 30})
    assert options.only_query_overrides({"priority": "frame_rate", "fps": None}) == {}
    assert options.only_query_overrides({"priority": "budget"}) == {"priority": "budget"}
    assert options.only_query_overrides({"error_margin": 0.002}) == {"error_margin": 0.002}
    assert options.only_query_overrides({"power_margin": 0.05, "error_margin": 0.0}) == {"power_margin": 0.05}
    assert set(options.PRIORITY_LABELS) == set(options.PRIORITIES)


@pytest.mark.blender
def test_addon_query_properties_have_the_schema_default_and_bounds(scene_props) -> None:
    """The frame-rate target and the priority are scene properties built from their declarations (0: the
    store's own rate), read back as the lookup's keywords, shown in the panel's budget box."""
    import importlib
    import inspect

    from tests.addon_support import EXT_MODULE

    properties = importlib.import_module(f"{EXT_MODULE}.properties")
    rna = scene_props.bl_rna.properties
    assert properties.option_values(scene_props, QUERY) == {o.name: o.default for o in QUERY}
    unset = {"fps": None, "priority": "frame_rate", "error_margin": 0.0, "power_margin": 0.0}
    assert properties.query_values(scene_props) == unset
    for opt in QUERY:
        prop = rna[opt.name]
        assert prop.description.lower().startswith(opt.help.lower())
        if opt.choices:
            assert tuple(item.identifier for item in prop.enum_items) == opt.choices
            assert tuple(item.name for item in prop.enum_items) == opt.choice_labels
        else:
            assert prop.hard_min == 0 and math.isclose(prop.hard_max, opt.maximum, rel_tol=1e-6)
        for text in _outside(opt):
            with pytest.raises(ValueError, match=opt.name):
                properties.set_option(scene_props, opt.name, _value(opt, text))
    properties.set_option(scene_props, "fps", 12.5)
    properties.set_option(scene_props, "priority", "budget")
    properties.set_option(scene_props, "error_margin", 0.002)
    properties.set_option(scene_props, "power_margin", 0.05)
    assert properties.query_values(scene_props) == pytest.approx({
        "fps": 12.5, "priority": "budget", "error_margin": 0.002, "power_margin": 0.05})
    properties.set_option(scene_props, "fps", None)
    assert scene_props.fps == 0 and properties.query_values(scene_props)["fps"] is None
    scene_props.property_unset("priority")  # as a .blend saved before the option existed reads it
    scene_props.property_unset("error_margin")
    scene_props.property_unset("power_margin")
    assert properties.query_values(scene_props) == unset
    panels = importlib.import_module(f"{EXT_MODULE}.panels")
    assert "option_schema.QUERY_OPTIONS" in inspect.getsource(panels._draw_budget)


@pytest.mark.blender
def test_batch_sets_a_saved_frame_rate_back_to_the_stores_own(scene_props) -> None:
    """A .blend saved with a Frame rate override keeps it when batch leaves --fps out, takes another
    rate, and ``--fps store`` sets it back to 0, the store's own rate (what the lookup then uses)."""
    import importlib

    from addon import batch
    from tests.addon_support import EXT_MODULE

    properties = importlib.import_module(f"{EXT_MODULE}.properties")

    def apply(*argv: str) -> dict:
        batch._apply_scene_options(EXT_MODULE, scene_props, batch.parser().parse_args(["playback", *argv]))
        return properties.query_values(scene_props)

    properties.set_option(scene_props, "fps", 12.0)
    assert apply() == {"fps": 12.0, "priority": "frame_rate", "error_margin": 0.0,
                       "power_margin": 0.0}  # left out: it stays
    assert apply("--fps", "store", "--priority", "budget") == {"fps": None, "priority": "budget",
                                                               "error_margin": 0.0, "power_margin": 0.0}
    assert scene_props.fps == 0.0
    assert apply("--fps", "50")["fps"] == 50.0
    assert apply("--fps", "store")["fps"] is None
    scene_props.property_unset("priority")


# -- options whose default is derived (None): a command-line word sets a saved value back -----------------
DERIVED = tuple(o for o in (*PUBLIC, *QUERY) if o.optional)


def test_the_options_whose_default_is_derived_are_the_known_ones() -> None:
    """Each optional option's None means "derive it" from the path or the store; a new one must get a
    word of its own (the next tests walk every one of them)."""
    assert {o.name: o.derived_word for o in DERIVED} == {"eval_width": "auto", "display_height": "path",
                                                         "fps": "store"}


@pytest.mark.parametrize("opt", DERIVED, ids=lambda o: o.name)
def test_every_derived_option_has_a_word_on_every_command_line_and_its_help(opt: options.Option) -> None:
    """The word (never a valid value) is what leaving the option out gives where that is the derived
    default (``render-budget optimize``, the demo's query options), and the marker that sets a saved
    value back in batch, where leaving it out keeps the .blend's value; both helps name it."""
    from addon import batch

    word = opt.derived_word
    assert word and opt.help
    with pytest.raises(ValueError):
        opt.check(word)
    batch_optimize = batch.parser()._subparsers._group_actions[0].choices["optimize"]
    assert getattr(_parse_batch(opt.cli_flag, word), opt.name) is options.DERIVE
    helps = {"batch optimize": (batch_optimize, f"the .blend's value stays; {word}: back to that default")}
    if opt in PUBLIC:
        assert options.from_arguments(_parse_batch(opt.cli_flag, word))[opt.name] is None
        assert getattr(_parse_cli(opt.cli_flag, word), opt.name) is None
        helps["render-budget optimize"] = (build_parser()._subparsers._group_actions[0].choices["optimize"],
                                           f"{word}: that default, as when left out")
    for name, (ap, says) in helps.items():
        text = " ".join(ap.format_help().split())
        assert f"{opt.cli_flag} {opt.metavar}|{word}" in text and says in text, (name, text)
    for text in (word.upper(), word + "s", "derive"):
        with pytest.raises(SystemExit):
            _parse_batch(opt.cli_flag, text)


def test_demo_display_height_path_prices_at_the_paths_own_resolution() -> None:
    """The demo's own display height (180) unless given; ``--display-height path`` is the path's own
    resolution (None, left to the service), as its help says."""
    from tools import demo

    def display_height(*argv: str) -> object:
        return demo.job_request(demo.parser().parse_args(list(argv))).option("display_height")

    assert display_height() == demo.DEMO_DISPLAY_HEIGHT
    assert display_height("--display-height", "path") is None
    assert display_height("--display-height", "360") == 360
    says = " ".join(demo.parser().format_help().split())
    assert "--display-height PX|path" in says
    assert "left out: the demo's own; path: back to that default" in says


@pytest.mark.blender
@pytest.mark.parametrize("opt", DERIVED, ids=lambda o: o.name)
def test_batch_sets_each_saved_derived_option_back_so_the_job_derives_it(scene_props, opt: options.Option
                                                                        ) -> None:
    """A value saved in the .blend stays when batch leaves the option out, is replaced by another, and the
    option's word sets it back to 0, the add-on's "derive it": the lookup's keywords (``fps``) or the
    optimisation job the add-on sends (the optimiser's options) then leave it to the store or service."""
    import importlib

    from addon import batch
    from tests.addon_support import EXT_MODULE

    properties = importlib.import_module(f"{EXT_MODULE}.properties")
    ops_optimize = importlib.import_module(f"{EXT_MODULE}.ops_optimize")
    declared = PUBLIC if opt in PUBLIC else QUERY

    def apply(*argv: str) -> object:
        batch._apply_scene_options(EXT_MODULE, scene_props, batch.parser().parse_args(["optimize", *argv]))
        return properties.option_values(scene_props, declared)[opt.name]

    low, high = (_value(opt, text) for text in _inside(opt)[:2])
    properties.set_option(scene_props, opt.name, high)
    assert apply() == high  # left out: the saved value stays
    assert apply(opt.cli_flag, str(low)) == low
    assert apply(opt.cli_flag, opt.derived_word) is None and getattr(scene_props, opt.name) == 0
    assert apply() is None  # and stays derived
    if opt in PUBLIC:  # what the Optimize job sends: the option left to the service, which derives it
        request = ops_optimize.job_request(scene_props.id_data)
        assert request.option(opt.name) is None
        assert opt.name not in request.payload("0" * 64, {})["options"]
        properties.set_option(scene_props, opt.name, high)
        sent = ops_optimize.job_request(scene_props.id_data).payload("0" * 64, {})["options"]
        assert sent[opt.name] == high
    else:
        assert properties.query_values(scene_props)[opt.name] is None
    properties.set_option(scene_props, opt.name, None)
