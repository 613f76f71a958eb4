"""``policy:FILE``: a learned policy, trained with stable-baselines3 on the flat lab env.

A policy file is the zip stable-baselines3 saves, with one more entry,
:data:`SPEC_ENTRY`: what the policy was trained on (the slot catalogue, the operations,
the sizes of the flat observation and action, the lab time of a training episode) and
the observation normalisation it learned behind (``VecNormalize``'s running mean and
variance).  The agent wraps its lab env in the training env's mapping
(:class:`~orthoglide_env.wrappers.FlatLabActions` and ``FlattenObservation``), normalises
each observation as training did, and draws its action from the policy's distribution
with the agent's own random stream (seeded per machine by ``compare``: an episode is
reproducible) until it has used the lab time of a training episode; then it stops, since
beyond that time the policy has never acted.  It sees what every agent sees, never the
machine's truth.

Why draw and not play the mean action: the lab's information reward pays for readings at
new postures, and a policy learns them as the spread of its actions around a mean that
barely moves; played alone, the mean drives to one posture and reads it again and again
(one policy of ``examples/train_policy.py``: 0.137 mm with its mean action, 0.054 mm
drawing, median over four held-out machines).

A file trained on another lab (a slot catalogue that has grown since, another number of
stands) is refused with the reason, before any episode (a catalogue that is no design's
when the file is read, another design's at the lab's reset): the policy's inputs and
outputs would mean other things.  ``examples/train_policy.py`` trains and saves one.
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.spaces import flatten, flatten_space

from calibrators.agents.actor_weights import read_actor
from calibrators.agents.base import Agent, LabRows, action
from orthoglide_env import (
    DESIGN_LAB_ENV_ID,
    DESIGN_LAB_V1_ENV_ID,
    DESIGN_LAB_V2_ENV_ID,
    FLAT_LAB_ENV_ID,
)
from orthoglide_env.instruments.dial import weighting_sigma
from orthoglide_env.lab.counting_rows import BUDGET, CLOCK, TAKEN, CountingRows, taken_of
from orthoglide_env.lab.design_belief import (
    SPECTRUM_VIEWS,
    DesignBelief,
    action_masks,
    observations,
    observe_many,
)
from orthoglide_env.lab.operations import OP_NAMES, SLOT_NAMES, V0_OPS, Op, slot_catalogue
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.wrappers import flat_action_space, lab_action

#: The entry of the policy zip that holds the :class:`PolicySpec` (JSON).
SPEC_ENTRY: str = "orthoglide_policy.json"
#: Version of that entry's layout: a file of another version is refused.
SPEC_VERSION: int = 1
INSTALL_HINT: str = "install the extra: pip install '.[rl]'"
#: The design views' env ids, by the view's version (its observation).
DESIGN_VIEW_IDS: dict[str, int] = {DESIGN_LAB_ENV_ID: 0, DESIGN_LAB_V1_ENV_ID: 1,
                                   DESIGN_LAB_V2_ENV_ID: 2}
#: How a design-view policy may play (:attr:`PolicySpec.play`).
PLAYS: tuple[str, ...] = ("draw", "argmax")
#: How a design-view policy's moves may let plungers down (:attr:`PolicySpec.flicks`).
FLICKS: tuple[str, ...] = ("prior", "filter", "shortlist", "ranked")
#: The filters beside the belief that a policy of ``flicks`` other than "prior" plays its
#: moves with, by name: a class made from (lab, belief, the lab's first observation),
#: registered by the module that defines it (:mod:`calibrators.planning.active_filter`
#: registers "filter"; the planner's modules import the agents package, not the reverse).
FLICK_FILTERS: dict[str, Any] = {}


@dataclass(frozen=True)
class PolicySpec:
    """What a saved policy was trained on, and how its observations were normalised."""

    algorithm: str  # the stable-baselines3 class, e.g. "PPO"
    slots: tuple[str, ...]  # the slot names of the training lab's catalogue
    ops: tuple[str, ...]  # OP_NAMES of the training lab
    stands: int
    observation_size: int
    action_size: int
    budget_s: float  # lab time of a training episode
    env: dict[str, Any]  # the lab env's keyword arguments in training (for the record)
    #: VecNormalize's running statistics of the flat observation (empty: not normalised).
    obs_mean: tuple[float, ...] = ()
    obs_var: tuple[float, ...] = ()
    clip_obs: float = 10.0
    epsilon: float = 1e-8
    version: int = SPEC_VERSION
    #: The training lab's machine design (``MachineDesign.to_dict``); None: the prototype
    #: (files saved before designs were recorded).
    design: dict[str, Any] | None = None
    #: The env id (and version) the policy acted in: the flat lab, or a design view
    #: (``OrthoglideLabDesign-v0``, ``-v1`` or ``-v2``, whose discrete operations the
    #: policy chooses).
    env_id: str = FLAT_LAB_ENV_ID
    #: How a design-view policy plays: "draw" from its distribution over the open
    #: operations, or "argmax", its most likely one (a policy that imitates a greedy
    #: expert learns one operation per state, and a draw only adds its residual spread).
    play: str = "draw"
    #: How a design-view policy's moves let plungers down: "prior", as the view's fixed
    #: plan does, or "filter", as ``active``'s filter of the values read does
    #: (:class:`~calibrators.planning.active_expert.FilteredDesignLab`), or "shortlist", as
    #: that filter does, choosing among ``active``'s short list only
    #: (:class:`~calibrators.planning.shortlist.ShortlistDesignLab`), or "ranked", the
    #: short list's ranks as actions and its moves' features seen after the view's
    #: observation (:class:`~calibrators.planning.shortlist.RankedShortlistLab`).
    flicks: str = "prior"
    #: Whether a policy of ``flicks="filter"`` also sees each posture's dials the filter
    #: lets read (:meth:`~calibrators.planning.active_filter.ActiveFilter.reach`).
    reach: bool = False

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> PolicySpec:
        data = json.loads(text)
        for key in ("slots", "ops", "obs_mean", "obs_var"):
            data[key] = tuple(data.get(key, ()))
        return cls(**data)

    def normalise(self, flat: np.ndarray) -> np.ndarray:
        """The observation as the policy saw it in training: VecNormalize's formula with
        its frozen statistics."""
        if not self.obs_mean:
            return flat
        scaled = (flat - np.asarray(self.obs_mean)) / np.sqrt(np.asarray(self.obs_var)
                                                              + self.epsilon)
        return np.clip(scaled, -self.clip_obs, self.clip_obs)


def spec_of(env: gym.Env, algorithm: str, env_kwargs: dict[str, Any],
            normaliser: Any | None = None, play: str = "draw") -> PolicySpec:
    """The spec of a policy trained on ``env``, the flat lab or the design view
    (:class:`~orthoglide_env.wrappers.DesignLab`) (``normaliser``: the training
    VecNormalize, or None; ``play``: :attr:`PolicySpec.play`)."""
    if play not in PLAYS:
        raise ValueError(f"play must be one of {PLAYS}, got {play!r}")
    lab = env.unwrapped
    rms = getattr(normaliser, "obs_rms", None)
    discrete = isinstance(env.action_space, gym.spaces.Discrete)
    return PolicySpec(
        algorithm=algorithm, slots=tuple(s.slot for s in lab.slots), ops=OP_NAMES[:V0_OPS],
        stands=int(lab.n_stands),
        observation_size=int(env.observation_space.shape[0]),
        action_size=int(env.action_space.n if discrete else env.action_space.shape[0]),
        budget_s=float(lab.budget_s),
        env=dict(env_kwargs),
        obs_mean=tuple(float(v) for v in rms.mean) if rms is not None else (),
        obs_var=tuple(float(v) for v in rms.var) if rms is not None else (),
        clip_obs=float(getattr(normaliser, "clip_obs", 10.0)),
        epsilon=float(getattr(normaliser, "epsilon", 1e-8)), design=lab.design.to_dict(),
        env_id=(_view_id(env.get_wrapper_attr("version")) if discrete else FLAT_LAB_ENV_ID),
        play=play,
        flicks=env.get_wrapper_attr("flicks") if discrete else "prior",
        reach=bool(getattr(env, "reach", False)),
    )


def _view_id(version: int) -> str:
    """The env id of the design view of ``version``."""
    return next(key for key, value in DESIGN_VIEW_IDS.items() if value == version)


def save_policy(model: Any, path: str | Path, spec: PolicySpec) -> Path:
    """Save the stable-baselines3 ``model`` to ``path`` (a zip, the name as given) with
    ``spec`` inside it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as handle:
        model.save(handle)
    with zipfile.ZipFile(path, "a") as archive:
        archive.writestr(SPEC_ENTRY, spec.to_json())
    return path


def read_spec(path: str | Path) -> PolicySpec:
    """The spec of the policy file ``path``, checked against this lab (no learning library
    needed): ``ValueError`` saying why it cannot run here."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no policy file '{path}' (train one: python examples/train_policy.py "
                         f"--out {path})")
    try:
        with zipfile.ZipFile(path) as archive:
            spec = PolicySpec.from_json(archive.read(SPEC_ENTRY).decode())
    except (zipfile.BadZipFile, KeyError, TypeError, ValueError):
        raise ValueError(f"'{path}' is not a policy file of this workbench (a zip saved by "
                         "examples/train_policy.py)") from None
    if spec.version != SPEC_VERSION:
        raise ValueError(f"policy file '{path}' has layout version {spec.version}, this "
                         f"workbench reads {SPEC_VERSION}: retrain it")
    if spec.env_id != FLAT_LAB_ENV_ID and spec.env_id not in DESIGN_VIEW_IDS:
        raise ValueError(f"policy file '{path}' acted in env '{spec.env_id}'; this workbench "
                         f"plays {[FLAT_LAB_ENV_ID, *DESIGN_VIEW_IDS]}: retrain it")
    if spec.play not in PLAYS:
        raise ValueError(f"policy file '{path}' plays '{spec.play}'; this workbench plays "
                         f"{list(PLAYS)}: retrain it")
    if spec.flicks not in FLICKS:
        raise ValueError(f"policy file '{path}' lets plungers down by '{spec.flicks}'; this "
                         f"workbench knows {list(FLICKS)}: retrain it")
    if not _a_catalogue(spec.slots) or spec.ops != OP_NAMES[:V0_OPS]:
        raise ValueError(
            f"policy file '{path}' was trained on a lab with {len(spec.slots)} slots and "
            f"operations {list(spec.ops)}; this lab has a design's slot catalogue (the "
            f"prototype's: {len(SLOT_NAMES)} slots) and {list(OP_NAMES[:V0_OPS])}: its actions and "
            "observations mean other things here, retrain it (examples/train_policy.py)")
    return spec


def _a_catalogue(names: tuple[str, ...]) -> bool:
    """Whether ``names`` are the slot catalogue of a design (the one whose bar slots the
    names place)."""
    try:
        at = tuple(float(n.split("@")[1]) for n in names if n.startswith("x-leg/y@"))
        design = dataclasses.replace(PROTOTYPE, slot_positions=at)
    except ValueError:
        return False
    return tuple(s.slot for s in slot_catalogue(design)) == names


@lru_cache(maxsize=4)
def _load_model(path: str, modified_ns: int, algorithm: str) -> Any:
    """The stable-baselines3 model in ``path``, loaded once per file version (an agent is
    made for every episode of a comparison)."""
    try:
        import stable_baselines3
    except ImportError:
        raise RuntimeError(f"running a learned policy needs stable-baselines3: "
                           f"{INSTALL_HINT}") from None
    cls = getattr(stable_baselines3, algorithm, None)
    if cls is None and algorithm == "MaskablePPO":
        try:
            from sb3_contrib import MaskablePPO as cls
        except ImportError:
            raise RuntimeError(f"running a MaskablePPO policy needs sb3-contrib: "
                               f"{INSTALL_HINT}") from None
    if cls is None:
        raise ValueError(f"policy file '{path}' names an unknown algorithm '{algorithm}'")
    return cls.load(path, device="cpu")


class PolicyAgent(Agent):
    """Plays the policy saved in ``path`` (see the module); not in the registry, made by
    ``get_agent("policy:PATH")``."""

    name = "policy"

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.spec = read_spec(self.path)
        self.model = _load_model(str(self.path.resolve()), self.path.stat().st_mtime_ns,
                                 self.spec.algorithm)
        space = self.model.action_space
        actions = (space.n,) if isinstance(space, gym.spaces.Discrete) else space.shape
        sizes = (self.model.observation_space.shape, actions)
        if sizes != ((self.spec.observation_size,), (self.spec.action_size,)):
            raise ValueError(f"policy file '{self.path}': the network's spaces {sizes} differ "
                             "from its spec: the file is damaged")

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        super().reset(env, observation, rng)
        self._check_lab()
        # The spaces alone: a lab in a vector env is no gymnasium.Env to wrap.
        self.spaces = (self.env.observation_space, self.env.action_space)
        sizes = (flatten_space(self.spaces[0]).shape[0], flat_action_space(self.spaces[1]).shape[0])
        self._check_sizes(sizes)

    def _check_sizes(self, sizes: tuple[int, int]) -> None:
        """Refuse a lab whose observation and action sizes are not the training lab's."""
        if sizes != (self.spec.observation_size, self.spec.action_size):
            raise ValueError(
                f"policy file '{self.path}' was trained on a lab of {self.spec.stands} "
                f"stands with {self.spec.observation_size} observations and "
                f"{self.spec.action_size} actions; this lab ({self.env.n_stands} stands, "
                f"tracker {'on' if self.env.tracker else 'off'}) has {sizes[0]} and "
                f"{sizes[1]}")

    def _check_lab(self) -> None:
        """Refuse a lab of another slot catalogue or design than the training lab's."""
        script = ("examples/train_masked.py" if self.spec.env_id in DESIGN_VIEW_IDS
                  else "examples/train_policy.py")
        slots = tuple(s.slot for s in self.env.slots)
        if self.spec.slots != slots:
            raise ValueError(
                f"policy file '{self.path}' was trained on a lab with {len(self.spec.slots)} "
                f"slots; this lab's design has {len(slots)} (bar slots at "
                f"{list(self.env.design.slot_positions)}): its actions and observations mean "
                f"other things here, retrain it on this design ({script})")
        trained = PROTOTYPE if self.spec.design is None else MachineDesign.from_dict(
            self.spec.design)
        if trained != self.env.design:
            here = self.env.design
            raise ValueError(
                f"policy file '{self.path}' was trained on machines of another design (L = "
                f"{trained.L:g} mm, limits [{trained.rho_min:g}, {trained.rho_max:g}] mm; this "
                f"lab's: L = {here.L:g} mm, [{here.rho_min:g}, {here.rho_max:g}] mm): its "
                f"actions and observations mean other things here, retrain it on this design "
                f"({script})")

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        if observation["time"][0] >= self.spec.budget_s:
            return action(Op.STOP)
        flat = flatten(self.spaces[0], observation)
        mean, std = self._distribution(self.spec.normalise(flat))
        # Clipped to the Box by the mapping, as stable-baselines3 clipped it in training.
        return lab_action(self.spaces[1], mean + std * self.rng.standard_normal(mean.shape))

    def _distribution(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and standard deviation of the policy's (diagonal Gaussian) action."""
        import torch

        with torch.no_grad():
            tensor, _ = self.model.policy.obs_to_tensor(flat)
            normal = self.model.policy.get_distribution(tensor).distribution
            return normal.mean.numpy()[0], normal.stddev.numpy()[0]


class DesignPolicyAgent(PolicyAgent):
    """Plays a policy trained on a design view (``OrthoglideLabDesign-v0``, ``-v1`` or
    ``-v2``, :class:`~orthoglide_env.wrappers.DesignLab`): it keeps the view's belief from
    the lab's observations (in view 2 its counts alone, not its covariance), draws the
    policy's operation among the open ones (its mask) with the agent's random stream, and
    plays it as the lab actions it is (a move's lever flicks, then the move), until the
    lab time of a training episode is used.  The belief runs on the training episode's
    budget, so that the observed clock and the mask mean what they
    meant in training.  Its network is read from the file in NumPy
    (:func:`~calibrators.agents.actor_weights.read_actor`): it plays without torch or
    stable-baselines3."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.spec = read_spec(self.path)
        self.actor = read_actor(self.path)
        sizes = (self.actor.weights[0].shape[1], self.actor.weights[-1].shape[0])
        if sizes != (self.spec.observation_size, self.spec.action_size):
            raise ValueError(f"policy file '{self.path}': the network's sizes {sizes} differ "
                             "from its spec: the file is damaged")

    def reset(self, env: gym.Env, observation: dict[str, np.ndarray],
              rng: np.random.Generator) -> None:
        Agent.reset(self, env, observation, rng)
        self._check_lab()
        lab = self.env
        version = DESIGN_VIEW_IDS[self.spec.env_id]
        # A view that observes no spectrum decides without the covariance, unless a filter
        # beside the belief reads it.
        self.belief = DesignBelief(lab.design, lab.n_stands,
                                   weighting_sigma(float(lab.noise.effective_sigma)),
                                   self.spec.budget_s, version,
                                   covariance=(version in SPECTRUM_VIEWS
                                               or self.spec.flicks != "prior"))
        size = len(self.belief.observation())
        self.belief.start(observation)
        self.filter = None
        if self.spec.flicks != "prior":
            if self.spec.flicks not in FLICK_FILTERS:
                raise ValueError(f"policy file '{self.path}' plays its moves with the "
                                 f"'{self.spec.flicks}' filter: import "
                                 "calibrators.planning.active_filter first")
            self.filter = FLICK_FILTERS[self.spec.flicks](lab, self.belief, observation)
        # A filter whose view adds inputs or names its own actions (a ranked short list)
        # says how many.
        extra = (self.belief.n_postures if self.spec.reach
                 else getattr(self.filter, "inputs", 0))
        self._check_sizes((size + extra,
                           getattr(self.filter, "actions", self.belief.n_actions)))
        self.queue: list[dict[str, Any]] = []
        self.last: dict[str, Any] | None = None

    @property
    def belief(self) -> DesignBelief:
        """The agent's belief.  Played in a chunk of counting agents (:func:`counting`),
        its state is kept in the chunk's rows; read here, it is written back first, and
        the agent leaves the chunk (the next chunk's rows start from the beliefs)."""
        chunk = self.__dict__.get("_chunk")
        if chunk is not None:
            chunk.rows.write_back(self._row, self._belief)
            self._leave()
        return self._belief

    @belief.setter
    def belief(self, value: DesignBelief) -> None:
        self._leave()
        self._belief = value

    def _leave(self) -> None:
        """Leave the chunk of counting agents this agent played in, if any: the chunk no
        longer holds all its agents' beliefs."""
        chunk = self.__dict__.get("_chunk")
        if chunk is not None:
            chunk.agents = None
        self._chunk = None

    def act(self, observation: dict[str, np.ndarray], info: dict[str, Any]) -> dict[str, Any]:
        return self.act_all([self], [observation], [info])[0]

    @classmethod
    def act_all(cls, agents: list[Agent], observations: list[dict[str, np.ndarray]],
                infos: list[Mapping[str, Any]]) -> list[dict[str, Any]]:
        """Each agent takes in its lab's observation (their beliefs together,
        :func:`~orthoglide_env.lab.design_belief.observe_many`, or the chunk's rows of
        counting agents, :func:`counting`); those that choose an operation now choose
        together (:func:`decide_all`, one network pass per policy file; counting agents
        once per distinct state); each plays its operation's next lab action, or stops
        once the training episode's time is used."""
        chunk = CountingChunk.of(agents)
        if chunk is not None:
            deciding = chunk.take_in(agents, observations, infos)
            if deciding.size:
                decide_counting(chunk.rows, chunk.index.take(deciding),
                                [agents[k] for k in deciding.tolist()])
            return _lab_actions(agents)
        following = [(agent, observation, info) for agent, observation, info
                     in zip(agents, observations, infos, strict=True) if agent.last is not None]
        observe_many([a.belief for a, _, _ in following], [a.last for a, _, _ in following],
                     [o for _, o, _ in following],
                     [bool(i.get("refused")) for _, _, i in following])
        for agent, observation, info in following:
            if agent.filter is not None:
                agent.filter.observe(agent.last, observation, info)
        deciding = [agent for agent, observation in zip(agents, observations, strict=True)
                    if not agent.queue and observation["time"][0] < agent.spec.budget_s]
        for group in _by_actor(deciding):
            for agent, chosen in zip(group, decide_all(group), strict=True):
                agent.queue = (agent.belief.operations(chosen) if agent.filter is None
                               else agent.filter.operations(chosen, agent.belief))
        return _lab_actions(agents)

    def decide(self) -> int:
        """An operation among the open ones (the mask), from the policy's network's logits
        in NumPy: as the spec's ``play`` says, the most likely one, or a draw of the masked
        softmax with the agent's random stream (the largest of the logits plus Gumbel
        noise).  A policy trained for a few minutes by PPO still spreads its choices, and
        its most likely operation, played alone, comes back to one posture again and again
        (the flat agent's finding too): such a policy draws.  :func:`decide_all` of this
        agent alone."""
        return decide_all([self])[0]


def _lab_actions(agents: list[DesignPolicyAgent]) -> list[dict[str, Any]]:
    """Each agent's next lab action: its operation's next, or stop when it has none.  An
    operation's lab action is made once for the agents that queued it together (a chunk's
    group of equal states, :func:`decide_counting`): the labs only read their actions."""
    made: dict[int, dict[str, Any]] = {}
    actions = []
    for agent in agents:
        if not agent.queue:
            actions.append(action(Op.STOP))
            continue
        last = agent.last = agent.queue.pop(0)
        # By the operation's id: the agents hold their operations throughout the call.
        lab = made.get(id(last))
        if lab is None:
            lab = made[id(last)] = action(last["op"], last["rho"], last["stand"], last["slot"])
        actions.append(lab)
    return actions


def counting(agents: list[DesignPolicyAgent]) -> bool:
    """Whether ``agents`` all play one network of view 2 (the readings' counts) by the
    view's own moves (no filter beside the belief, no inputs of one): their beliefs only
    count, and the chunk keeps them as rows (:class:`~orthoglide_env.lab.counting_rows.
    CountingRows`)."""
    first = agents[0]
    return (DESIGN_VIEW_IDS[first.spec.env_id] == 2 and not first.spec.reach
            and all(a.actor is first.actor and a.filter is None for a in agents))


class CountingChunk:
    """Counting agents (:func:`counting`) played together, their beliefs' rows
    (:class:`~orthoglide_env.lab.counting_rows.CountingRows`) and each agent's row
    (``agent._row``; ``agent._chunk`` is the chunk)."""

    def __init__(self, agents: list[DesignPolicyAgent]) -> None:
        self.rows = CountingRows([a.belief for a in agents])
        for k, agent in enumerate(agents):
            agent._chunk, agent._row = self, k
        #: The agents of the last call, in order (None once one has left), and their rows.
        self.agents: list[DesignPolicyAgent] | None = list(agents)
        self.index = np.arange(len(agents))

    @classmethod
    def of(cls, agents: list[DesignPolicyAgent]) -> CountingChunk | None:
        """The chunk that ``agents`` play in: the last call's (the same agents, or those of
        them still playing), else a new one of their beliefs as they are (each written
        back first); None unless they count (:func:`counting`)."""
        chunk = agents[0].__dict__.get("_chunk")
        if chunk is not None and chunk.agents is not None:
            if agents == chunk.agents:
                return chunk
            if all(a.__dict__.get("_chunk") is chunk for a in agents):
                chunk.agents, chunk.index = list(agents), np.array([a._row for a in agents])
                return chunk
        return cls(agents) if counting(agents) else None

    def take_in(self, agents: list[DesignPolicyAgent],
                observations: list[dict[str, np.ndarray]],
                infos: list[Mapping[str, Any]]) -> np.ndarray:
        """:meth:`DesignPolicyAgent.act_all`'s taking in for this chunk's ``agents`` (those
        of the last :meth:`of`): their rows take in the lab's step together; the agents
        (their positions) that choose an operation now, with no operation queued and
        before their budget's end."""
        following = [k for k, agent in enumerate(agents) if agent.last is not None]
        idle = np.array([k for k, agent in enumerate(agents) if not agent.queue],
                        dtype=np.int64)
        rows = self.rows
        if following:
            rows.observe(self.index if len(following) == len(agents)
                         else self.index[following], [agents[k].last for k in following],
                         *_taken(observations, infos, following))
        # A row's clock is its lab's time as it last took it in: this step's, where it
        # followed one, else the first observation's, which its belief started from.
        ready = rows.state[:, CLOCK] < rows.state[:, BUDGET]
        return idle[ready.take(self.index.take(idle))]


def _taken(observations: list[dict[str, np.ndarray]], infos: list[Mapping[str, Any]],
           following: list[int]) -> tuple[Mapping[str, np.ndarray], np.ndarray]:
    """The :data:`~orthoglide_env.lab.counting_rows.TAKEN` entries of the labs at positions
    ``following`` of ``observations``, stacked a row per lab, and whether each refused its
    operation (``infos``): read from their vector env's arrays in one call a field where
    they hand them over (:class:`~calibrators.agents.base.LabRows`), else lab by lab."""
    if isinstance(observations, LabRows) and isinstance(infos, LabRows):
        batch, info = observations.batch, infos.batch
        refused = info.get("refused")
        index = observations.index
        if len(following) < len(index):
            index = index[following]
        elif len(index) == len(batch["time"]) and (
                index.tobytes() == np.arange(len(index), dtype=index.dtype).tobytes()):
            # Every lab of the vector env, in its order: its arrays as they are.
            return (batch, np.zeros(len(index), dtype=bool) if refused is None
                    else refused.astype(bool) & info["_refused"])
        return ({key: batch[key][index] for key in TAKEN},
                np.zeros(len(index), dtype=bool) if refused is None
                else refused[index].astype(bool) & info["_refused"][index])
    if len(following) < len(observations):
        observations = [observations[k] for k in following]
        infos = [infos[k] for k in following]
    return taken_of(observations), np.array([bool(info.get("refused")) for info in infos],
                                            dtype=bool)


def decide_counting(rows: CountingRows, index: np.ndarray,
                    agents: list[DesignPolicyAgent]) -> None:
    """Each of ``agents`` (counting agents of ``rows`` ``index``) chooses its operation and
    queues its lab actions: the rows of equal states are grouped
    (:meth:`~orthoglide_env.lab.counting_rows.CountingRows.groups`), and each group's
    observation, mask and operation are found once, with one network pass for the groups
    (a draw's noise is each agent's own)."""
    reps, groups = rows.groups(index)
    parts = rows.parts(reps)
    seen, masks = rows.observations(reps, parts), rows.masks(reps, parts)
    first = agents[0]
    if first.spec.play == "draw":
        noise = np.array([agent.rng.gumbel(size=masks.shape[1]) for agent in agents])
        chosen = first.actor.choose_many(seen, masks, noise, groups)
    else:
        chosen = first.actor.choose_many(seen, masks).take(groups)
    keys = list(zip(groups.tolist(), chosen.tolist(), strict=True))
    made = {key: rows.operations(reps[key[0]], key[1], parts[key[0]].moves)
            for key in dict.fromkeys(keys)}
    for agent, key in zip(agents, keys, strict=True):
        agent.queue = made[key].copy()


def _by_actor(agents: list[DesignPolicyAgent]) -> list[list[DesignPolicyAgent]]:
    """``agents`` grouped by the network they play (one per policy file), in order."""
    groups: dict[int, list[DesignPolicyAgent]] = {}
    for agent in agents:
        groups.setdefault(id(agent.actor), []).append(agent)
    return list(groups.values())


def decide_all(agents: list[DesignPolicyAgent]) -> list[int]:
    """Each agent's operation (:meth:`DesignPolicyAgent.decide`), for agents of one
    network (one policy file, one view) on labs of one design: their observations in one
    batched pass (:func:`~orthoglide_env.lab.design_belief.observations`), their masks in
    another (:func:`~orthoglide_env.lab.design_belief.action_masks`, or each filter's),
    and the choices in one pass of the network (:meth:`ActorWeights.choose_many
    <calibrators.agents.actor_weights.ActorWeights.choose_many>`: the arg-max of the
    float64 logits over the open operations), so that a chunk of machines pays about one
    machine's call overhead; a draw's noise is each agent's, from its own stream."""
    if not agents:
        return []
    seen = observations([a.belief for a in agents])
    if agents[0].spec.reach:
        # float32, as the view in training gave it.
        seen = np.concatenate((seen, [a.filter.reach() for a in agents]),
                              axis=1).astype(np.float32)
    ranked = agents[0].spec.flicks == "ranked"
    if ranked:
        # The short list's features after the view's (float32, as in training); its
        # ranks are the actions.
        inputs, masks = zip(*[a.filter.ranked(a.belief) for a in agents], strict=True)
        seen = np.concatenate((seen, inputs), axis=1).astype(np.float32)
        masks = np.array(masks)
    else:
        masks = (action_masks([a.belief for a in agents]) if agents[0].filter is None
                 else np.array([a.filter.action_mask(a.belief) for a in agents]))
    noise = (np.array([a.rng.gumbel(size=masks.shape[1]) for a in agents])
             if agents[0].spec.play == "draw" else None)
    chosen = agents[0].actor.choose_many(seen, masks, noise).tolist()
    if ranked:
        return [a.filter.view_action(c, a.belief) for a, c in zip(agents, chosen, strict=True)]
    return chosen


def policy_agent(path: str | Path) -> PolicyAgent:
    """The agent that plays the policy file ``path``: of the flat lab or of the design
    view, as its spec says."""
    spec = read_spec(path)
    return DesignPolicyAgent(path) if spec.env_id in DESIGN_VIEW_IDS else PolicyAgent(path)
