"""Parameter space: packing round trips, fixed (inert) parameters, mapping to RenderSettings fields."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from service.params import (
    DEFAULT_VALUES,
    Parameter,
    ParameterSpace,
    default_space,
    parse_space_argument,
    renderable_space,
    search_space,
    space_from_texts,
    space_holding,
    stored_space,
    values_text,
)
from service.store import pack_indices


def test_default_space_shape() -> None:
    s = default_space()
    assert len(s.parameters) <= 8
    assert all(len(p.values) <= 16 for p in s.parameters)
    assert s.size == 5 * 3 * 4 * 4 * 4 * 3 * 4 * 2
    mq = s.max_quality_indices()
    assert mq == tuple(len(p.values) - 1 for p in s.parameters)  # values ordered cheapest first
    assert s.values_of(mq)["sampling"] == "fsaa_2x2"
    assert ParameterSpace.default() == s


@given(st.data())
def test_pack_roundtrip_in_default_space(data) -> None:
    s = default_space()
    idx = tuple(data.draw(st.integers(0, len(p.values) - 1)) for p in s.parameters)
    packed = s.pack(idx)
    assert packed == pack_indices(idx) and 0 <= packed < 2**32
    assert s.unpack(packed) == idx
    assert s.expand(s.restrict(idx)) == idx


def test_fixed_parameters_leave_the_search() -> None:
    s = default_space().fix_inert({"env_filter": "no glossy materials",
                                   "ao_samples": "no geometry to occlude", "mode": "only one of two fields"})
    assert s.fixed == {"env_filter": 2, "ao_samples": 3}
    assert s.size == default_space().size // (3 * 4)
    free = tuple(0 for _ in s.free_positions)
    full = s.expand(free)
    assert full[5] == 2 and full[6] == 3
    sub = s.subset(["max_depth", "shadow_samples"])
    assert sub.free_n_values == (4, 4)
    assert sub.fixed_reasons["sampling"] == "not searched"
    with pytest.raises(ValueError):
        s.subset(["nope"])


def test_fields_and_render_space() -> None:
    s = default_space()
    f = s.fields_of(s.max_quality_indices())
    assert f["mode"] == "fsaa" and f["block"] == 2 and f["max_depth"] == 3
    rs = s.as_render_space()
    assert rs["mode"] == ["undersample", "1spp", "supersample", "fsaa"] and rs["block"] == [4, 2]
    assert rs["shadow_samples"] == [0, 1, 4, 16]


def test_dict_roundtrip_and_validation() -> None:
    s = default_space().fix_inert({"multirate": "single tile"})
    assert ParameterSpace.from_dict(s.to_dict()) == s
    with pytest.raises(ValueError):
        Parameter("x", tuple(range(17)), 0)
    with pytest.raises(ValueError):
        Parameter("x", (1, 1), 0)
    with pytest.raises(ValueError):
        Parameter("x", (1, 2), 2)
    with pytest.raises(ValueError):
        ParameterSpace(tuple(Parameter(f"p{i}", (0, 1), 1) for i in range(9)))
    with pytest.raises(ValueError):
        s.pack([0] * 7)
    with pytest.raises(ValueError):
        s.unpack(0xF)  # sampling index 15 does not exist


def test_max_quality_maps_to_render_settings_max_quality() -> None:
    import sim_core

    s = default_space()
    got = s.to_settings(s.max_quality_indices())
    want = sim_core.RenderSettings.max_quality()
    for name in s.as_render_space():
        if name != "normal_threshold_deg":  # only adaptive modes read it; the maximum is FSAA
            assert getattr(got, name) == getattr(want, name), name
    cheap = s.to_settings(tuple(0 for _ in s.parameters))
    assert (cheap.mode, cheap.block, cheap.max_depth, cheap.resolution_scale) == ("undersample", 4, 0, 0.7)


def test_the_default_space_is_design_tables_cut_from_the_renderable_one() -> None:
    """Cache keys and recorded stores name the default space: cut from the renderable space, it must stay
    the explicit DESIGN.md table it was (values, best value, RenderSettings fields)."""
    s = default_space()
    assert {p.name: p.values for p in s.parameters} == DEFAULT_VALUES
    assert [p.max_quality for p in s.parameters] == [4, 2, 3, 3, 3, 2, 3, 1]
    assert s.parameters[3].fields == tuple({"shadow_samples": v} for v in (0, 1, 4, 16))
    r = renderable_space()
    assert r.fields_of(r.max_quality_indices()) == s.fields_of(s.max_quality_indices())  # same reference
    assert search_space() == s
    assert search_space({"ao_samples": [0, 10, 16]}).parameters[6].values == (0, 10, 16)


@given(st.data())
def test_values_cut_from_a_space_keep_its_order_and_its_best_value(data) -> None:
    r = renderable_space()
    wanted = {}
    for p in data.draw(st.lists(st.sampled_from(r.parameters), unique_by=lambda p: p.name, max_size=4)):
        wanted[p.name] = data.draw(st.lists(st.sampled_from(p.values), min_size=1, unique_by=repr))
    s = r.with_values(wanted)
    for p, q in zip(s.parameters, r.parameters, strict=True):
        if p.name not in wanted:
            assert p == q
            continue
        order = [q.values.index(v) for v in p.values]
        assert order == sorted(order) and set(map(repr, p.values)) == set(map(repr, wanted[p.name]))
        best = q.values.index(p.values[p.max_quality])
        assert all(abs(best - q.max_quality) <= abs(i - q.max_quality) for i in order)
        assert p.fields == tuple(q.fields[i] for i in order)  # each value keeps its RenderSettings fields


def test_space_values_from_the_command_line_and_from_a_store() -> None:
    assert parse_space_argument("shadow_samples=0,1,2,4,16") == ("shadow_samples", (0, 1, 2, 4, 16))
    assert parse_space_argument("resolution_scale=0.9, 1") == ("resolution_scale", (0.9, 1.0))
    assert parse_space_argument("multirate=True") == ("multirate", (True,))
    for bad, needle in (("shadow_samples=3", "'3' is not a value"), ("warp=1", "unknown parameter"),
                        ("ao_samples", "NAME=V1"), ("multirate=1", "not a value")):
        with pytest.raises(ValueError, match=needle):
            parse_space_argument(bad)
    with pytest.raises(ValueError, match="unknown parameters"):
        search_space({"warp": [1]})
    assert space_holding({"shadow_samples": 4}) == default_space()
    assert space_holding({"shadow_samples": 2}) == renderable_space()
    assert space_holding(None) == default_space()
    with pytest.raises(ValueError, match="not a value"):
        space_holding({"shadow_samples": 3}).indices_of({"shadow_samples": 3})
    finer = search_space({"ao_samples": [0, 4, 8, 10, 16]})
    assert stored_space(finer.to_stored()) == finer
    assert stored_space(default_space().to_stored()) == default_space()


@given(st.data())
def test_values_typed_in_the_parameter_list_become_a_space_only_where_they_differ(data) -> None:
    """The add-on's list shows each parameter's values as text; a job names only what was edited away
    from the default values (in any order), so an untouched list searches the default space."""
    r = renderable_space()
    texts, wanted = {}, {}
    for p in data.draw(st.lists(st.sampled_from(r.parameters), unique_by=lambda p: p.name, max_size=4)):
        values = data.draw(st.lists(st.sampled_from(p.values), min_size=1, unique_by=repr))
        texts[p.name] = values_text(values)
        if {repr(v) for v in values} != {repr(v) for v in DEFAULT_VALUES[p.name]}:
            wanted[p.name] = tuple(values)
    space = space_from_texts(texts)
    assert space == wanted
    assert search_space(space) == r.with_values({**DEFAULT_VALUES, **wanted})


def test_the_default_values_as_text_ask_for_no_space_and_a_bad_value_is_named() -> None:
    texts = {name: values_text(values) for name, values in DEFAULT_VALUES.items()}
    assert space_from_texts(texts) == {}
    assert space_from_texts({"shadow_samples": "16, 4, 1, 0"}) == {}  # the order does not matter
    assert space_from_texts({"shadow_samples": "  "}) == {}  # blank: the default values
    assert space_from_texts({"ao_samples": "0, 10, 16"}) == {"ao_samples": (0, 10, 16)}
    with pytest.raises(ValueError, match="'3' is not a value of 'shadow_samples'"):
        space_from_texts({"shadow_samples": "0, 3"})
    with pytest.raises(ValueError, match="'' is not a value"):
        space_from_texts({"ao_samples": "0, , 4"})

