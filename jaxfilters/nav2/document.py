"""Internal: a ROS 2 params document read strictly -> nodes, typed parameters and topic names.

What `jaxfilters.nav2.params` needs of the file before it knows about filters:

* `read_document` reads the file as strictly as a map YAML (a regular file
  of at most `MAX_PARAMS_BYTES`, `map_decode.parse_yaml` with no aliases,
  merge keys or duplicate keys and at most `MAX_PARAMS_DEPTH` levels);
* `nodes_of` lists its nodes (namespace segments + name) with their
  parameters flattened to dotted names, ROS wildcard entries (`/**:`)
  merged in under the node's own values;
* `Reader` gives one node's parameters typed, with the launch file's
  placeholder substitutions applied;
* `resolve_topic` / `parent_namespace` resolve topic names as ROS does.

Every problem raises `Nav2ParamsError` (a ValueError) with a message cut to
at most `MAX_MESSAGE` characters; values in messages go through `show`.
"""

from __future__ import annotations

import dataclasses
import fnmatch
from collections.abc import Mapping
from typing import Any

from jaxfilters import validate
from jaxfilters.map_decode import read_regular_file
from jaxfilters.strict_yaml import parse_yaml

__all__ = ["MAX_MESSAGE", "MAX_NAME_CHARS", "MAX_PARAMS_BYTES", "MAX_PARAMS_DEPTH", "REQUIRED", "Nav2ParamsError",
           "Node", "Reader", "cut", "nodes_of", "parent_namespace", "read_document", "resolve_topic", "show"]

# Nav2's bringup nav2_params.yaml is about 18 KB; 1 MiB leaves room for fleets of namespaced
# robots and bounds the parser's time and memory.
MAX_PARAMS_BYTES = 1 << 20
# Nesting allowed in a params file: node namespaces, ros__parameters, and nested parameters
# (a zone filter's setpoints reach 7 levels in Nav2's layout).
MAX_PARAMS_DEPTH = 32
# A dotted parameter name or a node name: Nav2's longest are under 80 characters. The cap also
# bounds what flattening nested parameters can build (every leaf holds its whole dotted name).
MAX_NAME_CHARS = 256
# Wildcard node entries are matched against every node: at most this many pairs.
_MAX_WILDCARD_PAIRS = 1 << 20
MAX_MESSAGE = 600


class Nav2ParamsError(ValueError):
  """A Nav2 params file (or a `load_params` argument) that cannot be read as Nav2 would.

  The message names the file, the node and the key, and stays short for any
  input (values are cut). A ValueError, so `except ValueError` catches it.
  """

  def __init__(self, message: str):
    super().__init__(cut(str(message), MAX_MESSAGE))


def show(value: Any) -> str:
  """A bounded repr (`validate.short_repr`): time and length do not grow with the value's size."""
  return validate.short_repr(value, 200)


def cut(text: str, limit: int) -> str:
  """`text` cut in the middle to at most `limit` characters."""
  if len(text) <= limit:
    return text
  half = (limit - 5) // 2
  return f"{text[:half]} ... {text[-half:]}"


# `Reader.get`'s default for a parameter that must be present.
REQUIRED = object()
_KINDS = {"bool": "a bool (true/false)", "int": "an integer", "float": "a number",
          "str": "a string", "str_list": "a list of strings", "value": "a value"}


@dataclasses.dataclass
class Node:
  """One node of a params document: where it lives and its parameters."""
  segments: tuple[str, ...]          # namespace segments + node name
  params: dict[str, Any]             # dotted parameter name -> YAML value

  @property
  def name(self) -> str:
    return self.segments[-1]

  @property
  def namespace(self) -> str:
    return "".join("/" + s for s in self.segments[:-1])

  @property
  def full_name(self) -> str:
    return self.namespace + "/" + self.name


def _flatten(tree: dict, prefix: str, out: dict, where: str) -> dict:
  """Nested parameters -> {dotted name: value} (the depth is bounded by the YAML reader)."""
  for key, value in tree.items():
    name = prefix + str(key)
    if len(name) > MAX_NAME_CHARS:
      raise Nav2ParamsError(f"{where}: parameter name '{cut(name, 80)}' has {len(name)} characters; "
                            f"at most {MAX_NAME_CHARS} are allowed")
    if isinstance(value, dict):
      _flatten(value, name + ".", out, where)
    elif name in out:
      raise Nav2ParamsError(f"{where}: parameter '{name}' is given twice")
    else:
      out[name] = value
  return out


def _segments(key, path: str) -> list[str]:
  text = str(key)
  if len(text) > MAX_NAME_CHARS:
    raise Nav2ParamsError(f"{path}: node name '{cut(text, 80)}' has {len(text)} characters; at most "
                          f"{MAX_NAME_CHARS} are allowed")
  return [s for s in text.split("/") if s]


def _wildcard_match(pattern: tuple[str, ...], segs: tuple[str, ...]) -> bool:
  """ROS 2 wildcard node matching: '**' any number of segments, '*' / '?' inside one.

  A table over (pattern prefix, name prefix), so time stays len(pattern) x
  len(segs) however many '**' a pattern has.
  """
  # match[j]: pattern[:i] matches segs[:j], for the current i.
  match = [True] + [False] * len(segs)
  for part in pattern:
    if part == "**":
      for j in range(1, len(segs) + 1):
        match[j] = match[j] or match[j - 1]
    else:
      match = [False] + [match[j - 1] and fnmatch.fnmatchcase(segs[j - 1], part) for j in range(1, len(segs) + 1)]
  return match[-1]


def nodes_of(doc: dict, path: str) -> list[Node]:
  """Every node of a ROS 2 params document, wildcard parameters merged in (node's own win)."""
  concrete: dict[tuple[str, ...], dict] = {}
  wild: list[tuple[tuple[str, ...], dict]] = []

  def walk(tree: dict, segs: tuple[str, ...]):
    for key, value in tree.items():
      if key == "ros__parameters":
        where = f"{path}: node '/{'/'.join(segs)}'"
        if not segs:
          raise Nav2ParamsError(f"{path}: 'ros__parameters' at the top level belongs to no node")
        if value is None:
          value = {}
        if not isinstance(value, dict):
          raise Nav2ParamsError(f"{where}: ros__parameters must be a mapping; got {show(value)}")
        flat = _flatten(value, "", {}, where)
        if any("*" in s for s in segs):
          wild.append((segs, flat))
        else:
          concrete.setdefault(segs, {}).update(flat)
      elif isinstance(value, dict):
        walk(value, segs + tuple(_segments(key, path)))

  walk(doc, ())
  if len(wild) * len(concrete) > _MAX_WILDCARD_PAIRS:
    raise Nav2ParamsError(f"{path}: {len(wild)} wildcard node entries x {len(concrete)} nodes; at most "
                          f"{_MAX_WILDCARD_PAIRS} pairs are matched")
  nodes = []
  for segs, params in concrete.items():
    merged = {}
    for pattern, flat in wild:
      if _wildcard_match(pattern, segs):
        merged.update(flat)
    merged.update(params)
    nodes.append(Node(segs, merged))
  return nodes


def resolve_topic(topic: str, namespace: str, where: str, key: str) -> str:
  """An absolute topic name: '/x' as is, 'x' inside `namespace`."""
  if not topic:
    raise Nav2ParamsError(f"{where}: parameter '{key}' must name a topic; got an empty string")
  if topic.startswith("~"):
    raise Nav2ParamsError(f"{where}: parameter '{key}': private topic names ('~/...') are not supported; "
                     f"got {topic!r}")
  full = topic if topic.startswith("/") else f"{namespace}/{topic}"
  return "".join("/" + s for s in full.split("/") if s)


def parent_namespace(namespace: str) -> str:
  """The parent of a namespace, "/a/b" -> "/a" ("" stays ""), as ROS joinWithParentNamespace uses it."""
  return namespace.rsplit("/", 1)[0] if namespace else ""


class Reader:
  """Typed access to one node's parameters with placeholder substitution.

  `where` ("file: node '/ns/name'") starts every message; `get(key, kind,
  default)` returns the parameter as `kind` ("bool", "int", "float", "str",
  "str_list", "value") or raises Nav2ParamsError naming the key.
  """

  def __init__(self, node: Node, path: str, substitutions: Mapping[str, Any], used: set[str]):
    self.node = node
    self.where = f"{path}: node '{node.full_name}'"
    self._subs = substitutions
    self._used = used

  def has(self, key: str) -> bool:
    return key in self.node.params

  def get(self, key: str, kind: str, default: Any = REQUIRED) -> Any:
    if key not in self.node.params:
      if default is REQUIRED:
        raise Nav2ParamsError(f"{self.where}: missing required parameter '{key}'")
      return default
    value = self.node.params[key]
    placeholder = None
    if isinstance(value, str) and value in self._subs:
      self._used.add(value)
      placeholder, value = value, self._subs[value]
      if isinstance(value, str) and kind != "str":
        try:
          value = parse_yaml(value, f"substitution {show(placeholder)}", what="YAML literal",
                             max_depth=MAX_PARAMS_DEPTH)
        except ValueError:
          pass  # stays a string: reported below as not a literal of this kind
    return self._check(key, value, kind, placeholder)

  def _check(self, key: str, v: Any, kind: str, placeholder: str | None) -> Any:
    ok = {"bool": isinstance(v, bool),
          "int": isinstance(v, int) and not isinstance(v, bool),
          "float": isinstance(v, (int, float)) and not isinstance(v, bool),
          "str": isinstance(v, str),
          "str_list": isinstance(v, list) and all(isinstance(s, str) for s in v),
          "value": v is not None and not isinstance(v, dict)}[kind]
    if ok and kind == "float":
      try:
        return float(v)
      except OverflowError:
        raise Nav2ParamsError(f"{self.where}: parameter '{key}' must fit float32; got an integer of "
                              f"{v.bit_length()} bits") from None
    if ok:
      return v
    msg = f"{self.where}: parameter '{key}' must be {_KINDS[kind]}; got {show(v)}"
    if placeholder is not None:
      msg += f" from substitution {show(placeholder)}"
    elif isinstance(v, str) and kind != "str":
      msg += (f", an unresolved launch placeholder? pass substitutions={{{show(v)}: ...}} "
              f"(CLI: --set {cut(v, 60)}=VALUE)")
    raise Nav2ParamsError(msg)


def read_document(path: str) -> dict:
  """The params document, read as strictly as a map YAML (see the module docstring)."""
  try:
    text = read_regular_file(path, "params file", max_bytes=MAX_PARAMS_BYTES)
    doc = parse_yaml(text, cut(path, 200), what="params YAML", max_depth=MAX_PARAMS_DEPTH)
  except FileNotFoundError as e:
    raise FileNotFoundError(cut(str(e), MAX_MESSAGE)) from None
  except ValueError as e:
    raise Nav2ParamsError(str(e)) from None
  if not isinstance(doc, dict):
    raise Nav2ParamsError(f"{path}: a params file must be a mapping of node names to "
                     f"'ros__parameters:'; got {type(doc).__name__}")
  return doc

