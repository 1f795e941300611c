"""The paper's transition equations, replayed from the TBox's schemas."""
import itertools
import random
import time

import pytest

from planhrc.errors import DeadlineExceeded
from planhrc.model import make_object
from planhrc.paths import default_tbox_path
from planhrc.pipeline import action_motion, merge_macro_steps
from planhrc.kb_service.store.records import ActionSpec, StoredAction
from planhrc.transition import StateIndex, TransitionError, _bindings, apply, replay
from planhrc.translator.domain import read_domain_model


def test_absolute_rotation_propagates_downstream_only():
    obj = make_object("o", "absolute", 3, 4)
    domain = read_domain_model(default_tbox_path(), "absolute")
    actions, states = replay(domain, obj.state([0, 90, 180]), ["(rotateclockwise o_l2 o_l1 o_j2 deg_90 deg_180)"])
    assert obj.joint_values_of(states[-1]) == {1: 0, 2: 180, 3: 270}
    assert len(actions[0].cond_eff) == 1  # only j3 is affected (j2 is the rotated joint itself)
    assert ("affected", "o_j3", "o_l2", "o_j2") in actions[0].cond_eff[0].when


def test_relative_rotation_changes_one_joint():
    obj = make_object("o", "relative", 4, 4)
    domain = read_domain_model(default_tbox_path(), "relative")
    _, states = replay(domain, obj.state([0, 90, 180]), ["(rotateanticlockwise o_l3 o_l2 o_j2 deg_90 deg_0)"])
    assert obj.joint_values_of(states[-1]) == {1: 0, 2: 0, 3: 180}


@pytest.mark.parametrize(
    "step,match",
    [("(rotateclockwise o_l1 o_l2 o_j2 deg_0 deg_90)", "precondition"),
     ("(rotateclockwise o_l1 o_l2 o_j1)", "takes 5 arguments"),
     ("(fly o_l1)", "not a schema")],
)
def test_inapplicable_steps_are_refused(step, match):
    obj = make_object("o", "relative", 3, 4)
    domain = read_domain_model(default_tbox_path(), "relative")
    with pytest.raises(TransitionError, match=match):
        replay(domain, obj.state([0, 0]), [step])


def test_apply_does_not_change_its_input():
    obj = make_object("o", "relative", 3, 4)
    domain = read_domain_model(default_tbox_path(), "relative")
    init = obj.state([0, 0])
    snapshot = set(init)
    actions, _ = replay(domain, init, ["(rotateclockwise o_l2 o_l1 o_j1 deg_0 deg_90)"])
    apply(init, actions[0])
    assert set(init) == snapshot


def _stored(step: int, text: str) -> StoredAction:
    name, *params = text.strip("()").split()
    return StoredAction(f"a{step}", step, ActionSpec(name, tuple(params), frozenset(), frozenset(), frozenset()))


def test_action_motion_relative_upstream_turn_is_opposite():
    obj = make_object("o", "relative", 4, 8)
    down = action_motion(obj, _stored(1, "(rotateclockwise o_l3 o_l2 o_j2 deg_0 deg_45)"))
    up = action_motion(obj, _stored(1, "(rotateclockwise o_l2 o_l3 o_j2 deg_0 deg_45)"))
    assert down["delta_deg"] == 45 and down["turned_link_index"] == 3 and down["held_link_index"] == 2
    assert up["delta_deg"] == -45 and up["turned_link_index"] == 2


def test_macro_steps_merge_consecutive_same_joint_same_direction():
    obj = make_object("o", "absolute", 3, 8)
    actions = [
        _stored(1, "(rotateclockwise o_l2 o_l1 o_j2 deg_0 deg_45)"),
        _stored(2, "(rotateclockwise o_l2 o_l1 o_j2 deg_45 deg_90)"),
        _stored(3, "(rotateanticlockwise o_l2 o_l1 o_j2 deg_90 deg_45)"),
        _stored(4, "(rotateclockwise o_l3 o_l2 o_j3 deg_0 deg_45)"),
    ]
    merged = merge_macro_steps(obj, actions)
    assert [(m.first_step, m.last_step, m.delta_deg) for m in merged] == [(1, 2, 90), (3, 3, -45), (4, 4, 45)]
    assert merged[0].expected_state_step == 3
    assert merged[0].action_ids == ("a1", "a2")


def _brute_force_bindings(literals, variables, binding, state, objects):
    """Every binding of `variables` over `objects` under which the literals hold, the slow obvious way."""
    from planhrc.grounding import holds
    found = []
    for values in itertools.product(objects, repeat=len(variables)):
        b = {**binding, **dict(zip(variables, values))}
        if all(holds(lit, b, state) for lit in literals):
            found.append(b)
    return found


@pytest.mark.parametrize("seed", range(4))
def test_indexed_join_finds_exactly_the_brute_force_bindings(seed):
    rng = random.Random(seed)
    obj = make_object("o", "absolute", 5, 4)
    domain = read_domain_model(default_tbox_path(), "absolute")
    state = obj.state([rng.choice([0, 90, 180, 270]) for _ in range(5)])
    objects = sorted({arg for atom in state for arg in atom[1:]})
    index = StateIndex(state)
    for schema in domain.actions:
        for ce in schema.conditional_effects:
            variables = [v for v, _ in ce.variables]
            for l1, j1 in [("o_l2", "o_j2"), ("o_l3", "o_j3"), ("o_l1", "o_j1")]:
                binding = {"?l1": l1, "?j1": j1}
                fast = list(_bindings(ce.when, variables, binding, index))
                slow = _brute_force_bindings(ce.when, variables, binding, state, objects)
                key = lambda b: sorted(b.items())  # noqa: E731
                assert sorted(fast, key=key) == sorted(slow, key=key) and slow


def _every_position(index):
    """The index with every (predicate, position) of its state indexed (as joins looking them all up would)."""
    for atom in list(index.state):
        for pos in range(len(atom) - 1):
            index.by_arg(atom[0], pos, atom[pos + 1])
    return index


def _same_index(mine, fresh):
    """Whether a moved index describes what a fresh one of its state does, on the positions it indexed."""
    for predicate, positions in mine._positions.items():
        for pos in positions:
            fresh.by_arg(predicate, pos, "")
    return all({k: v for k, v in a.items() if v} == {k: v for k, v in b.items() if v}
               for a, b in ((mine._by_pred, fresh._by_pred), (mine._by_arg, fresh._by_arg)))


def test_a_moved_index_equals_a_fresh_one_along_a_plan():
    obj = make_object("o", "absolute", 6, 8)
    domain = read_domain_model(default_tbox_path(), "absolute")
    steps = ["(rotateclockwise o_l3 o_l2 o_j3 deg_0 deg_45)", "(rotateclockwise o_l5 o_l4 o_j5 deg_45 deg_90)",
             "(rotateanticlockwise o_l2 o_l1 o_j2 deg_0 deg_315)"]
    _, states = replay(domain, obj.state([0] * 6), steps)
    index = _every_position(StateIndex(states[0]))
    for later in states[1:]:
        index.moved(later)
        assert _same_index(index, StateIndex(later))
    assert len(index._positions["hasorientation"]) == 2
    assert obj.joint_values_of(states[-1]) == {1: 0, 2: 315, 3: 0, 4: 0, 5: 45, 6: 45}


def test_replay_stops_at_its_deadline_without_a_result():
    obj = make_object("o", "absolute", 3, 4)
    domain = read_domain_model(default_tbox_path(), "absolute")
    with pytest.raises(DeadlineExceeded, match="after 0 of 1 steps"):
        replay(domain, obj.state([0, 0, 0]), ["(rotateclockwise o_l2 o_l1 o_j2 deg_0 deg_90)"],
               deadline_at=time.monotonic() - 1.0)


def test_a_remembered_step_grounds_as_a_fresh_one_and_is_still_refused_where_it_does_not_apply():
    """`Grounder` remembers the ground actions of schemas without conditional effects: the same action as
    `ground_action`, and a remembered step whose precondition fails is refused as before, naming it."""
    from planhrc.transition import Grounder, ground_action

    obj = make_object("o", "relative", 4, 4)
    domain = read_domain_model(default_tbox_path(), "relative")
    grounder = Grounder(domain)
    state = obj.state([0, 90, 180])
    step = "(rotateclockwise o_l3 o_l2 o_j2 deg_90 deg_180)"
    first = grounder.ground(step, state)
    again = grounder.ground(step, state)
    assert first == again == ground_action(domain, step, state)
    moved = apply(state, first)  # j2 is at 180 now: the same step no longer applies
    with pytest.raises(TransitionError, match="precondition"):
        grounder.ground(step, moved)
    rng = random.Random(3)
    for _ in range(200):  # random steps in random states: remembered or not, the same answer as a fresh one
        values = [rng.choice([0, 90, 180, 270]) for _ in range(3)]
        k = rng.randrange(1, 4)
        now = values[k - 1]
        then = rng.choice([0, 90, 180, 270])
        name = rng.choice(["rotateclockwise", "rotateanticlockwise"])
        text = f"({name} o_l{k + 1} o_l{k} o_j{k} deg_{now} deg_{then})"
        s = obj.state(values)
        try:
            expected = ground_action(domain, text, s)
        except TransitionError as exc:
            with pytest.raises(TransitionError, match=str(exc).split(":")[0]):
                grounder.ground(text, s)
            continue
        assert grounder.ground(text, s) == expected


def test_a_step_with_conditional_effects_grounds_as_a_fresh_one_in_every_state_and_for_other_static_facts():
    """`Grounder` keeps a conditional step's bindings the static facts allow and checks only the fluents per
    state: the same action as `ground_action` along random plans, for two objects of different sizes (other static
    facts), and a step whose precondition fails is refused."""
    from planhrc.transition import Grounder, ground_action

    domain = read_domain_model(default_tbox_path(), "absolute")
    grounder = Grounder(domain)
    rng = random.Random(8)
    for links in (4, 6, 4):
        obj = make_object("o", "absolute", links, 8)
        state = obj.state([rng.choice(obj.orientation_degrees) for _ in obj.joint_indices])
        statics = grounder.statics(state)
        for _ in range(120):
            k = rng.randrange(1, links + 1)
            now = obj.joint_values_of(state)[k]
            clockwise = rng.random() < 0.5
            then = (now + (45 if clockwise else -45)) % 360
            name = "rotateclockwise" if clockwise else "rotateanticlockwise"
            step = f"({name} o_l{k} o_l{k - 1} o_j{k} deg_{now} deg_{then})"
            fresh = ground_action(domain, step, state)
            assert grounder.ground(step, state, statics=statics) == fresh
            assert grounder.ground(step, state) == fresh  # without the caller's statics too
            state = apply(state, fresh)
        with pytest.raises(TransitionError, match="precondition"):
            grounder.ground(step, state, statics=statics)  # the last step again: its joint has moved on


def test_the_static_facts_of_one_problem_are_one_set_whatever_objects_hold_them():
    """`Grounder.statics` gives the set it gave last for equal static facts, so that what is kept for them is found
    by identity: states of one problem whose atoms are other objects (a planning worker's jobs come unpickled)
    share one set; another problem's facts get their own, and the steps ground as fresh ones either way."""
    import pickle

    from planhrc.transition import Grounder, ground_action

    domain = read_domain_model(default_tbox_path(), "absolute")
    grounder = Grounder(domain)
    obj = make_object("o", "absolute", 5, 8)
    state = obj.state([0, 45, 90, 135, 180])
    first = grounder.statics(state)
    copied = pickle.loads(pickle.dumps(obj.state([90, 90, 0, 45, 315])))  # the same statics, new objects
    assert grounder.statics(copied) is first
    other = make_object("o", "absolute", 6, 8).state([0] * 6)
    assert grounder.statics(other) is not first and grounder.statics(other) == frozenset(
        a for a in other if a[0] not in {"hasorientation"})
    step = "(rotateclockwise o_l3 o_l2 o_j3 deg_0 deg_45)"  # j3 at 0 in both states
    for s in (copied, obj.state([90, 0, 0, 45, 315])):
        for _ in range(2):  # the second time from what was kept
            assert grounder.ground(step, s, statics=grounder.statics(s)) == ground_action(domain, step, s)


def test_bimanual_turns_that_differ_only_in_orientations_and_grippers_share_their_bindings():
    """A bimanual turn's conditional effect names only its turned link and joint: steps that differ in their
    orientations or grippers share the bindings the static facts allow (one set per action, link and joint), and
    each still grounds as `ground_action` grounds it, along random plans from random states."""
    from planhrc.pipeline import config_from_settings, plan
    from planhrc.settings import make_settings
    from planhrc.transition import Grounder, ground_action

    domain = read_domain_model(default_tbox_path(), "bimanual")
    grounder = Grounder(domain)
    config = config_from_settings(make_settings(validate_plans=False))
    obj = make_object("o", "bimanual", 5, 24)
    rng = random.Random(6)
    turns, steps = set(), set()
    for _ in range(12):
        state = obj.state(obj.joint_values_from_links([rng.choice(obj.orientation_degrees) for _ in range(5)]))
        goal = obj.configuration_atoms(obj.joint_values_from_links([rng.choice(obj.orientation_degrees)
                                                                    for _ in range(5)]))
        outcome = plan(obj, state, goal, config)
        assert outcome.solved
        for _ in range(2):  # a step is kept from its second grounding on: both paths, each plan twice
            now = state
            statics = grounder.statics(now)
            for step in outcome.steps:
                fresh = ground_action(domain, step, now)
                assert grounder.ground(step, now, statics=statics) == fresh
                now = apply(now, fresh)
                if step.startswith("(rotate"):
                    name, turned, _, joint, *_ = step.strip("()").split()
                    turns.add((name, turned, joint))
                    steps.add(step)
    kept = grounder._bindings_of  # shared per action and the parameters its conditional effects name
    assert 0 < len(kept) <= len(turns) < len(steps) / 2


def test_a_step_of_a_large_absolute_object_grounds_in_its_state_as_a_fresh_one():
    """Past `Grounder.MAX_CANDIDATES` static bindings (40 joints x 18 orientations) a conditional step is ground in
    its state each time instead of kept: still the action `ground_action` gives, refused where it does not apply,
    and the replay's index (moved by each step's change, not by comparing states) ends as a fresh one."""
    from planhrc.transition import Grounder, apply_change, ground_action

    links, k = 40, 18
    obj = make_object("o", "absolute", links, k)
    domain = read_domain_model(default_tbox_path(), "absolute")
    grounder = Grounder(domain)
    rng = random.Random(4)
    step_deg = 360 // k
    state = obj.state([rng.choice(obj.orientation_degrees) for _ in obj.joint_indices])
    index = StateIndex(state)
    steps = []
    for _ in range(25):
        j = rng.randrange(1, links + 1)
        now = obj.joint_values_of(state)[j]
        clockwise = rng.random() < 0.5
        then = (now + (step_deg if clockwise else -step_deg)) % 360
        name = "rotateclockwise" if clockwise else "rotateanticlockwise"
        step = f"({name} o_l{j} o_l{j - 1} o_j{j} deg_{now} deg_{then})"
        fresh = ground_action(domain, step, state)
        assert len(fresh.cond_eff) == links - j  # every joint downstream of j moves with it
        assert grounder.ground(step, state) == grounder.ground(step, state, index) == fresh
        after, (removed, added) = apply_change(state, fresh)
        assert after == apply(state, fresh) and removed == state - after and added == after - state
        index.moved(after, (removed, added))
        state = after
        steps.append(step)
    with pytest.raises(TransitionError, match="precondition"):
        grounder.ground(steps[-1], state)  # the last step again: its joint has moved on
    assert index._positions and _same_index(index, StateIndex(state))


# -- the replay against the generic one: every formulation, random plans ------------------------------------------
def _generic_ground(domain, step, state):
    """The ground action of a step as the transition equations define it, with nothing of the replay's: the
    schema's literals bound by the step's arguments, each conditional effect's bindings enumerated by the generic
    join (`_bindings`, on a fresh index of the state), the effects instantiated, in `ground_action`'s order."""
    from planhrc.grounding import holds, instantiate
    from planhrc.model import EQUALITY, CondEffect
    from planhrc.transition import _cond_order, find_schema, parse_step

    name, args = parse_step(step)
    schema = find_schema(domain, name)
    binding = {var: value for (var, _), value in zip(schema.parameters, args)}
    if not all(holds(lit, binding, state) for lit in schema.precondition):
        raise TransitionError(f"{step}: not applicable")
    conds = [CondEffect(frozenset(instantiate(lit, b) for lit in ce.when if lit.predicate != EQUALITY and not lit.negated),
                        frozenset(instantiate(lit, b) for lit in ce.effects if lit.negated),
                        frozenset(instantiate(lit, b) for lit in ce.effects if not lit.negated))
             for ce in schema.conditional_effects
             for b in _bindings(ce.when, [v for v, _ in ce.variables], binding, StateIndex(state))]
    return ActionSpec(name, args,
                      frozenset(instantiate(lit, binding) for lit in schema.precondition
                                if lit.predicate != EQUALITY and not lit.negated),
                      frozenset(instantiate(lit, binding) for lit in schema.effects if lit.negated),
                      frozenset(instantiate(lit, binding) for lit in schema.effects if not lit.negated),
                      tuple(sorted(conds, key=_cond_order)))


def _generic_replay(domain, init, plan):
    """Eq. (statetransitioncond) step by step, every state made whole: `apply` on the generic ground action."""
    states, actions = [frozenset(init)], []
    for step in plan:
        actions.append(_generic_ground(domain, step, states[-1]))
        states.append(apply(states[-1], actions[-1]))
    return tuple(actions), tuple(states)


def _random_turns(obj, rng, n):
    """A random plan of `n` single-step turns of an absolute or relative object, each applicable in the state the
    ones before it lead to (an absolute turn moves the joints downstream too)."""
    domain = read_domain_model(default_tbox_path(), obj.formulation.value)
    init = state = obj.state([rng.choice(obj.orientation_degrees) for _ in range(obj.n_joints)])
    step = 360 // obj.orientations
    plan = []
    for _ in range(n):
        k = rng.choice(obj.joint_indices)
        now = obj.joint_values_of(state)[k]
        clockwise = rng.random() < 0.5
        then = (now + (step if clockwise else -step)) % 360
        name = "rotateclockwise" if clockwise else "rotateanticlockwise"
        turned, held = (k, k - 1) if obj.formulation.value == "absolute" else (k + 1, k)
        plan.append(f"({name} {obj.ident}_l{turned} {obj.ident}_l{held} {obj.ident}_j{k} deg_{now} deg_{then})")
        state = apply(state, _generic_ground(domain, plan[-1], state))
    return init, plan


@pytest.mark.parametrize("formulation", ["absolute", "relative", "bimanual"])
def test_the_replay_is_the_generic_replay_on_random_plans(formulation):
    """`replay` (its join fixed per condition, the steps kept by `Grounder`, one state changed in place and kept
    as changes) gives the actions and expected states of the generic replay (a fresh join per binding, `apply`
    making each state whole) on random plans of every formulation: random turns of absolute and relative objects,
    and the planner's plans of bimanual ones (grasps, moves to the centre and turns). Each plan is replayed twice:
    the second time its steps come from what `Grounder` kept the first time."""
    from planhrc import pipeline
    from planhrc.pipeline.config import config_from_settings
    from planhrc.settings import get_settings

    domain = read_domain_model(default_tbox_path(), formulation)
    rng = random.Random({"absolute": 1, "relative": 2, "bimanual": 3}[formulation])
    cases = []
    for links, k in ((3, 4), (5, 8), (9, 12), (4, 24)):
        obj = make_object("r", formulation, links, k)
        if formulation == "bimanual":
            config = config_from_settings(get_settings())
            for _ in range(2):
                init = obj.state([rng.choice(obj.orientation_degrees) for _ in range(obj.n_joints)])
                goal = obj.configuration_atoms([rng.choice(obj.orientation_degrees) for _ in range(obj.n_joints)])
                outcome = pipeline.plan(obj, init, goal, config, defer_validation=True)
                if outcome.solved and outcome.steps:
                    cases.append((init, outcome.steps))
        else:
            cases += [_random_turns(obj, rng, 3 * links) for _ in range(2)]
    assert len(cases) >= 6
    for init, plan in cases:
        expected_actions, expected_states = _generic_replay(domain, init, plan)
        for _ in range(2):
            actions, states = replay(domain, init, plan)
            assert actions == expected_actions
            assert len(states) == len(expected_states) and list(states) == list(expected_states)
            assert states[-1] == expected_states[-1] and states == expected_states


def test_expected_states_read_in_any_order_are_the_replayed_states_and_pickle_as_changes():
    """`ExpectedStates` read forwards, backwards, at random and by slices gives the states of the generic replay;
    pickled, it is far smaller than its states whole; `matching_states` gives the states a perceived state is
    subsumed by, latest first, as a check of every state whole does (perceived states on and off the plan)."""
    import pickle

    from planhrc.transition import ExpectedStates, matching_states

    obj = make_object("o", "absolute", 12, 12)
    domain = read_domain_model(default_tbox_path(), "absolute")
    rng = random.Random(5)
    init, plan = _random_turns(obj, rng, 40)
    _, whole = _generic_replay(domain, init, plan)
    _, states = replay(domain, init, plan)
    assert isinstance(states, ExpectedStates) and len(states) == len(whole) == 41
    order = list(range(41)) + list(range(40, -1, -1)) + [rng.randrange(41) for _ in range(60)]
    assert all(states[i] == whole[i] for i in order) and states[-3:] == whole[-3:]
    again = pickle.loads(pickle.dumps(states))
    assert again == whole and list(again) == list(whole)
    assert len(pickle.dumps(states)) < 0.6 * len(pickle.dumps(whole))
    perceived = [whole[i] | {("hasorientation", "deg_0", "o_j1")} for i in (0, 7, 40)] + list(whole[::5]) + [
        obj.state([rng.choice(obj.orientation_degrees) for _ in range(12)]) for _ in range(5)]
    for seen in perceived:
        brute = [i for i in range(40, -1, -1) if whole[i] <= seen]
        assert list(matching_states(seen, states)) == list(matching_states(seen, whole)) == brute
    fresh = ExpectedStates(states.first, states.changes)  # no last state given: made alone, then the others
    assert fresh[40] == whole[40] and list(fresh) == list(whole)
    with pytest.raises(IndexError):
        states[41]
