"""``NEATConfig``: every knob of tensor NEAT, validated, with sourced defaults.

Sources of the defaults, cited per field:
- [Qiu19] Qiu, Garratt, Howard & Anavatti 2019 (the reference paper, ``shared/paper``).
- [NEAT02] Stanley & Miikkulainen 2002, "Evolving Neural Networks through Augmenting
  Topologies", Evolutionary Computation 10(2), section 4.1 (parameters of the XOR and
  pole-balancing experiments).
- [NEATC] Stanley's NEAT C++ release (v1.2.1), where the paper is silent: link-weight
  mutation power 2.5 and weights capped at +-8.
- [NP] neat-python's defaults, where none of the above says.

Field names follow neat-python's INI keys where a key exists, so ``NEATConfig.from_ini``
reads a neat-python config file; ``[Qiu19]``-specific knobs (``sigma_*``,
``compatibility_sigma_coefficient``) extend it.
"""

from __future__ import annotations

import configparser
import dataclasses
import math
import os
from dataclasses import dataclass, field, fields

__all__ = ["NEATConfig", "ConfigError", "config_defaults"]


class ConfigError(ValueError):
    """A config value is out of range or of the wrong type; the message names the field."""


def _range(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False,
           integer: bool = False) -> dict:
    return {"range": (lo, hi, lo_open, hi_open), "integer": integer}


@dataclass(frozen=True)
class NEATConfig:
    """Tensor-NEAT configuration. Immutable; ``dataclasses.replace`` makes variants."""

    # --- network layout --------------------------------------------------------------
    num_inputs: int = field(default=2, metadata=_range(1, None, integer=True))
    num_outputs: int = field(default=1, metadata=_range(1, None, integer=True))
    # [NEAT02] uses a bias input with constant activation 1; spiking controllers in
    # [Qiu19] have none (their neurons get a background current instead).
    num_bias: int = field(default=1, metadata=_range(0, None, integer=True))
    # The bias nodes' value: 1 [NEAT02]; NEAT C++ 1.2.1's pole balancing feeds 0.5 ([NEATC]
    # ``cartpole`` experiments: ``input[...] = .5``). A sigmoid network holds its bias nodes at 1
    # and scales their outgoing weights by it (the same sums); a spiking one injects this many
    # times its full input current.
    bias_value: float = field(default=1.0, metadata=_range(None, None))
    # Hidden-node slots per genome index. Fixed, so a run's numbers never depend on the
    # other runs in its batch; slots no genome of a run uses any more are reclaimed, so a
    # run never dies of a full index (an add-node that finds no free slot is skipped and
    # counted in the statistics).
    max_hidden: int = field(default=32, metadata=_range(0, None, integer=True))
    # [Qiu19] start: each input wired to each output, nothing else. neat-python's "full"
    # start for recurrent nets also adds output self-loops: ``initial_self_loops=True``.
    initial_self_loops: bool = False
    # Hidden nodes of the start genome (neat-python's ``num_hidden``): slots
    # ``[first_hidden, first_hidden + initial_hidden)``, each fed by every input and bias and
    # feeding every output, beside the direct input-output genes. 0 ([Qiu19], [NEAT02]): none.
    initial_hidden: int = field(default=0, metadata=_range(0, None, integer=True))
    # Feed-forward only (no cycles): [NEAT02]'s XOR. Spiking controllers are recurrent.
    feed_forward: bool = False

    # --- population and termination -------------------------------------------------
    pop_size: int = field(default=150, metadata=_range(2, None, integer=True))  # [Qiu19], [NEAT02]
    fitness_threshold: float = math.inf  # [NP] key; run(..., fitness_target) overrides

    # --- connection genes -----------------------------------------------------------
    weight_init_mean: float = 0.0  # [NP]
    weight_init_stdev: float = field(default=1.0, metadata=_range(0, None))  # [NP]
    # How a new weight is drawn (a start genome's, a new link's, a replaced one's), as [NP]'s
    # ``weight_init_type``: False, Gaussian ``mean + stdev N(0, 1)``; True, uniform in
    # ``[max(min, mean - 2 stdev), min(max, mean + 2 stdev)]`` ([NP]'s ``uniform``). [NEATC]
    # draws its start and new-link weights uniform in +-1 (mean 0, stdev 0.5).
    weight_init_uniform: bool = False
    weight_max_value: float = field(default=8.0, metadata=_range(0, None, lo_open=True))  # [NEATC]
    weight_min_value: float = -8.0  # [NEATC]
    # [NEAT02]: 80 % of genomes get weight mutations; each weight then is perturbed (90 %)
    # or replaced by a new random value (10 %).
    weight_mutate_rate: float = field(default=0.8, metadata=_range(0, 1))
    weight_replace_rate: float = field(default=0.1, metadata=_range(0, 1))
    # Gaussian stdev of a perturbation. [NEATC] perturbs by up to +-2.5; on XOR (50 seeds,
    # 100 generations) 2.5 failed 5 runs, 1.44 failed 9, neat-python's 0.5 failed 16.
    weight_mutate_power: float = field(default=2.5, metadata=_range(0, None))  # [NEATC]
    # [NP] instead: every gene of every child decides alone, perturbed with
    # ``weight_mutate_rate``, else replaced with ``weight_replace_rate``, else left unchanged.
    weight_mutate_per_gene: bool = False
    conn_add_prob: float = field(default=0.1, metadata=_range(0, 1))  # [Qiu19], [NEAT02] small pops
    node_add_prob: float = field(default=0.03, metadata=_range(0, 1))  # [Qiu19], [NEAT02]
    # [NP] enabled_mutate_rate: per-gene chance to flip the enabled flag.
    enabled_mutate_rate: float = field(default=0.01, metadata=_range(0, 1))
    # [NEAT02]: a gene disabled in either parent is disabled in the child with 75 % chance.
    disabled_inherit_prob: float = field(default=0.75, metadata=_range(0, 1))

    # --- decoder gain sigma ([Qiu19] eq. 12; values are ours, [Qiu19] gives none) -----
    sigma_init_mean: float = field(default=1.0, metadata=_range(0, None, lo_open=True))
    sigma_init_stdev: float = field(default=0.0, metadata=_range(0, None))
    sigma_mutate_rate: float = field(default=0.2, metadata=_range(0, 1))
    sigma_mutate_power: float = field(default=0.1, metadata=_range(0, None))
    sigma_min_value: float = field(default=1e-3, metadata=_range(0, None, lo_open=True))  # positive [Qiu19]
    sigma_max_value: float = field(default=10.0, metadata=_range(0, None, lo_open=True))

    # --- speciation: delta = c1 E/N + c2 D/N + c3 W + c4 |sigma_a - sigma_b| ----------
    # Slot markings carry no creation order, so excess and disjoint genes are told apart by
    # slot order (a gene beyond the other genome's highest occupied slot is excess).
    compatibility_excess_coefficient: float = field(default=1.0, metadata=_range(0, None))  # [NEAT02] c1
    compatibility_disjoint_coefficient: float = field(default=1.0, metadata=_range(0, None))  # [NEAT02] c2
    compatibility_weight_coefficient: float = field(default=0.4, metadata=_range(0, None))  # [NEAT02] c3
    compatibility_sigma_coefficient: float = field(default=1.0, metadata=_range(0, None))  # [Qiu19] c4; value ours
    compatibility_threshold: float = field(default=3.0, metadata=_range(0, None, lo_open=True))  # [NEAT02]
    # [NEAT02]: N = genes in the larger genome, but N = 1 when both have fewer than 20.
    compatibility_normalize_min_genes: int = field(default=20, metadata=_range(1, None, integer=True))

    # --- stagnation ------------------------------------------------------------------
    max_stagnation: int = field(default=15, metadata=_range(1, None, integer=True))  # [NEAT02]
    # Species protected from stagnation (the best ones); [NEAT02] keeps the top 2.
    species_elitism: int = field(default=2, metadata=_range(0, None, integer=True))
    # When every species of a run is gone: restart that run from a fresh population [NP].
    reset_on_extinction: bool = True

    # --- reproduction ([Qiu19]: (150,150)-ES plus species elitism) ---------------------
    survival_threshold: float = field(default=0.2, metadata=_range(0, 1, lo_open=True))  # [Qiu19] best 20 %
    # [NEATC] ``Species::adjust_fitness``: a species' best ``floor(survival_threshold * size + 1)``
    # members are its parents (at most all), one more than ``ceil(survival_threshold * size)``
    # whenever ``survival_threshold * size`` is whole. Off: ``ceil`` ([NP], at least one).
    survival_neatc: bool = False
    # [Qiu19]: the champion of each species with more than 5 members is copied unchanged.
    # [NP] copies its ``elitism`` = 2 best of every species (``elitism_min_species_size`` 1).
    elitism: int = field(default=1, metadata=_range(0, None, integer=True))
    elitism_min_species_size: int = field(default=6, metadata=_range(1, None, integer=True))
    # [NEAT02]: 25 % of offspring come from mutation alone, 75 % from crossover.
    crossover_prob: float = field(default=0.75, metadata=_range(0, 1))
    # [NEAT02]: interspecies mating rate 0.001.
    interspecies_crossover_prob: float = field(default=0.001, metadata=_range(0, 1))

    # --- [NEATC] mechanisms (``evolution.neat121`` has the presets); every default keeps
    # the behaviour above ---------------------------------------------------------------
    # Stagnant species: 0 removes them ([NEAT02]); a positive factor keeps them and
    # multiplies their fitness by it when offspring are shared out ([NEATC]
    # ``Species::adjust_fitness``: 0.01 after ``dropoff_age`` = ``max_stagnation``).
    stagnant_fitness_factor: float = field(default=0.0, metadata=_range(0, 1))
    # [NEATC] ``Species::adjust_fitness`` reads a species' stagnation clock before it records
    # this generation's improvement: a species stagnant until now is still stagnant in the
    # generation it improves. Off: the clock restarts first (a species improving now is not).
    stagnation_clock_before: bool = False
    # Every this many generations the worst species at least ``obliterate_min_age``
    # generations old (the best one if none is) counts as stagnant from then on
    # ([NEATC] ``Population::epoch``: 30 and 20). 0: never.
    obliterate_interval: int = field(default=0, metadata=_range(0, None, integer=True))
    obliterate_min_age: int = field(default=20, metadata=_range(1, None, integer=True))
    # Whole-population stagnation: when a run's best fitness has not improved for this
    # many generations, only its two best species get offspring (half each), all clones of
    # their champions (the last as it is, the others with a new link, 20 %, else every weight
    # mutated), and their stagnation clocks and the run's restart ([NEATC]
    # ``highest_last_changed >= dropoff_age + 5``: 20, "delta coding"). 0: never.
    population_stagnation: int = field(default=0, metadata=_range(0, None, integer=True))
    # [NEATC] ``Species::reproduce``: a child gets add-node with ``node_add_prob``, else
    # add-connection with ``conn_add_prob``, else the weight, sigma and enabled mutations.
    mutation_exclusive: bool = False
    # [NEATC] ``mate_only_prob`` (0.2): a child of crossover is left unmutated with this probability.
    mate_only_prob: float = field(default=0.0, metadata=_range(0, 1))
    # [NEATC] ``Genome::mutate_link_weights`` instead of [NEAT02]'s rule: a genome mutating its
    # weights (``weight_mutate_rate``) changes every gene by a uniform step in
    # +-``weight_mutate_power``; half the genomes ("severe") replace 20 % of their genes by such
    # a value and keep 10 %; otherwise the last fifth of a genome of 10+ genes (slot order) is
    # replaced 20 %, kept 30 %, and the rest are perturbed.
    weight_mutate_neatc: bool = False
    # [NEATC] ``mate_multipoint_avg_prob`` (0.4): a crossover averages the weights of matching
    # genes with this probability, else takes each from either parent ([NEAT02]).
    crossover_average_prob: float = field(default=0.0, metadata=_range(0, 1))
    # [NEATC] ``Genome::mutate_add_link``: a new connection is recurrent (a self-loop, one
    # closing a cycle of enabled genes, or one into or out of an output) with
    # ``recur_only_prob`` and otherwise not; none is added when no free slot is of the kind
    # drawn. Off: any free slot.
    conn_add_recurrence: bool = False
    recur_only_prob: float = field(default=0.0, metadata=_range(0, 1))  # [NEATC] 0 DPV, 0.2 DPNV
    # [NEATC] ``newlink_tries`` (20): the new connection is drawn as ``Genome::mutate_add_link``
    # draws it, up to this many tries, each a random pair (from any present node to a present
    # non-input node; in the recurrent draw every other try, on average, a self-loop of a random
    # non-input node), the first one that is free and of the kind drawn taken; none when every
    # try fails. Sampled exactly from that distribution with one uniform. 0: uniformly among
    # the free slots of the kind.
    conn_add_tries: int = field(default=0, metadata=_range(0, None, integer=True))
    # [NEATC] ``Genome::mutate_add_link`` with the generation's innovation list: a new link a
    # genome of the same run already added this generation (the same slot, drawn as recurrent
    # or not alike) takes that genome's weight, the first in child order. Off: each its own draw.
    conn_add_shared_weight: bool = False
    # [NEATC] ``Species::reproduce``: each child joins the first species, in the order species
    # were founded, whose representative is within the threshold, the representative being the
    # species' champion of the parents' generation. Off: the closest representative, a random
    # member ([NP], [NEAT02]).
    speciate_neatc: bool = False
    # [NEATC] ``Genome::mutate_add_node``'s choice of the gene to split: 20 random tries of a gene,
    # the first enabled one not leaving a bias node taken (none if all 20 miss). Off: any enabled
    # gene, uniformly ([NEAT02]).
    node_add_neatc: bool = False
    # [NEATC] ``Gene::mutation_num``: the compatibility distance's weight term reads each gene's
    # weight as of its genome's last weight mutation (``Genomes.mutation_num``), not its weight:
    # 0 for the genes of a new node and for a link a genome of the run already added this
    # generation, the first such link's weight for it; the mean of the parents' for an averaged
    # gene. Off: the weights ([NEAT02]).
    compat_mutation_num: bool = False
    # [NEATC] ``mutate_toggle_enable_prob`` (0.1 DPNV): one random gene (slot order) flips its
    # enabled flag, but is only disabled if its source keeps another enabled gene.
    toggle_enable_prob: float = field(default=0.0, metadata=_range(0, 1))
    # [NEATC] ``mutate_gene_reenable_prob`` (0.05 DPNV): the first disabled gene (slot order) is enabled.
    gene_reenable_prob: float = field(default=0.0, metadata=_range(0, 1))

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type in ("bool", bool):
                if not isinstance(value, bool):
                    raise ConfigError(f"NEATConfig.{f.name} must be true or false, got {value!r}")
                continue
            spec = f.metadata
            integer = spec.get("integer", False)
            if integer:
                if isinstance(value, bool) or not isinstance(value, int):
                    raise ConfigError(f"NEATConfig.{f.name} must be an integer, got {value!r}")
            elif isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
                raise ConfigError(f"NEATConfig.{f.name} must be a number, got {value!r}")
            lo, hi, lo_open, hi_open = spec.get("range", (None, None, False, False))
            bad_lo = lo is not None and (value <= lo if lo_open else value < lo)
            bad_hi = hi is not None and (value >= hi if hi_open else value > hi)
            if bad_lo or bad_hi or (not integer and f.name != "fitness_threshold" and math.isinf(value)):
                raise ConfigError(f"NEATConfig.{f.name} must be in {_describe(lo, hi, lo_open, hi_open)}, got {value!r}")
        if self.weight_min_value >= self.weight_max_value:
            raise ConfigError(
                f"NEATConfig.weight_min_value ({self.weight_min_value}) must be below weight_max_value "
                f"({self.weight_max_value})")
        if self.initial_hidden > self.max_hidden:
            raise ConfigError(f"NEATConfig.initial_hidden ({self.initial_hidden}) must not exceed max_hidden "
                              f"({self.max_hidden})")
        if self.weight_mutate_neatc and self.weight_mutate_per_gene:
            raise ConfigError("NEATConfig.weight_mutate_neatc and weight_mutate_per_gene are two rules for the "
                              "same mutation: set at most one")
        if self.sigma_min_value > self.sigma_max_value:
            raise ConfigError(
                f"NEATConfig.sigma_min_value ({self.sigma_min_value}) must not exceed sigma_max_value "
                f"({self.sigma_max_value})")

    # --- derived layout --------------------------------------------------------------
    @property
    def num_nodes(self) -> int:
        """Capacity of the node index: inputs, bias, outputs, then hidden slots."""
        return self.num_inputs + self.num_bias + self.num_outputs + self.max_hidden

    @property
    def first_output(self) -> int:
        return self.num_inputs + self.num_bias

    @property
    def first_hidden(self) -> int:
        return self.num_inputs + self.num_bias + self.num_outputs

    # --- INI -------------------------------------------------------------------------
    @classmethod
    def from_ini(cls, path: str | os.PathLike, **overrides) -> NEATConfig:
        """Read a neat-python-style INI file (any section); unknown keys raise ``ConfigError``.

        Keys neat-python has that this implementation does not use (activation options,
        node bias/response genes, ...) are listed in ``IGNORED_INI_KEYS`` and skipped.
        """
        parser = configparser.ConfigParser()
        try:
            with open(path, encoding="utf-8") as fh:
                parser.read_file(fh)
        except (OSError, configparser.Error) as exc:
            raise ConfigError(f"cannot read NEAT config {os.fspath(path)!r}: {exc}") from exc
        known = {f.name: f for f in fields(cls)}
        values: dict = {}
        for section in parser.sections():
            for key, raw in parser.items(section):
                key = INI_ALIASES.get(key, key)
                if key == "num_hidden" and raw.strip() not in ("0", ""):
                    raise ConfigError(f"{os.fspath(path)}: [{section}] num_hidden must be 0: its start "
                                      "depends on initial_connection, which is not read; pass "
                                      "initial_hidden=... (a full_direct start) as an override instead")
                if key in IGNORED_INI_KEYS:
                    continue
                if key == "weight_init_type":  # [NP]'s spelling of weight_init_uniform
                    values["weight_init_uniform"] = _parse_init_type(raw, f"{os.fspath(path)}: [{section}] {key}")
                    continue
                if key not in known:
                    raise ConfigError(f"{os.fspath(path)}: [{section}] {key} is not a NEATConfig field")
                values[key] = _parse(known[key], raw, f"{os.fspath(path)}: [{section}] {key}")
        values.update(overrides)
        return cls(**values)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def config_defaults() -> dict:
    """Each ``NEATConfig`` field's default (the value a config stored before the field existed had)."""
    return {f.name: f.default if f.default is not dataclasses.MISSING else f.default_factory()
            for f in dataclasses.fields(NEATConfig)
            if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING}


INI_ALIASES = {"initial_connection": "_initial_connection"}
IGNORED_INI_KEYS = {
    "fitness_criterion", "no_fitness_termination", "_initial_connection", "num_hidden",
    "activation_default", "activation_mutate_rate", "activation_options", "aggregation_default",
    "aggregation_mutate_rate", "aggregation_options", "bias_init_mean", "bias_init_stdev",
    "bias_max_value", "bias_min_value", "bias_mutate_power", "bias_mutate_rate", "bias_replace_rate",
    "bias_init_type", "response_init_mean", "response_init_stdev", "response_max_value",
    "response_min_value", "response_mutate_power", "response_mutate_rate", "response_replace_rate",
    "response_init_type", "conn_delete_prob", "node_delete_prob", "enabled_default",
    "enabled_rate_to_true_add", "enabled_rate_to_false_add", "single_structural_mutation",
    "structural_mutation_surer", "species_fitness_func",
    "min_species_size", "compatibility_disjoint_coefficient_nodes", "seed",
}


def _parse(f: dataclasses.Field, raw: str, where: str):
    text = raw.strip()
    if f.type in ("bool", bool):
        lowered = text.lower()
        if lowered in ("true", "yes", "on", "1"):
            return True
        if lowered in ("false", "no", "off", "0"):
            return False
        raise ConfigError(f"{where} must be true or false, got {raw!r}")
    if f.metadata.get("integer"):
        try:
            return int(text)
        except ValueError:
            raise ConfigError(f"{where} must be an integer, got {raw!r}") from None
    try:
        return float(text)
    except ValueError:
        raise ConfigError(f"{where} must be a number, got {raw!r}") from None


def _parse_init_type(raw: str, where: str) -> bool:
    """[NP]'s ``weight_init_type``: ``gaussian`` (or ``normal``) or ``uniform``; True for uniform."""
    text = raw.strip().lower()
    if text in ("gaussian", "normal", "uniform"):
        return text == "uniform"
    raise ConfigError(f"{where} must be gaussian, normal or uniform, got {raw!r}")


def _describe(lo, hi, lo_open, hi_open) -> str:
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    return f"{left}{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}{right}"
