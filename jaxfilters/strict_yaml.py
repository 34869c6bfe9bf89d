"""Strict, bounded YAML reading: one reader for every YAML file the library takes.

Map YAMLs (`map_decode.parse_map_yaml`) and Nav2 params files
(`jaxfilters.nav2`) are parsed here: PyYAML's safe loader (libyaml's when
installed) minus aliases (no billion-laughs documents), merge keys, duplicate
keys and nesting deeper than a cap the caller gives. The aliases, the depth
and same-spelled duplicate keys are refused from the event stream before
anything is built, so time and memory stay bounded by the text's length, and
every message names the file, the key path and the line.
"""

from __future__ import annotations

from typing import Any

import yaml

from jaxfilters.validate import short_repr

__all__ = ["parse_yaml"]

_ERROR_TEXT_LIMIT = 200


def _cut(text: Any, limit: int = _ERROR_TEXT_LIMIT) -> str:
  text = " ".join(str(text).split())
  return text if len(text) <= limit else text[:limit - 3] + "..."


# libyaml's parser when PyYAML has it: the pure-Python scanner is slow on hostile text.
_YamlBase = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _StrictYamlLoader(_YamlBase):
  """PyYAML's safe loader that also refuses merge keys and duplicate keys.

  A duplicate key would make one of two values win silently; a merge key
  (`<<`) needs an alias or hides which value a key has.
  """

  def construct_mapping(self, node, deep=False):
    if isinstance(node, yaml.MappingNode):
      seen = set()
      for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
          raise yaml.constructor.ConstructorError(
              None, None, "YAML merge keys (<<) are not allowed", key_node.start_mark)
        key = self.construct_object(key_node, deep=True)
        try:
          duplicate = key in seen
        except TypeError:
          raise yaml.constructor.ConstructorError(
              None, None, f"unhashable mapping key {short_repr(key, 40)}",
              key_node.start_mark) from None
        if duplicate:
          raise yaml.constructor.ConstructorError(
              None, None, f"duplicate key {short_repr(key, 40)}", key_node.start_mark)
        seen.add(key)
    return super().construct_mapping(node, deep)


class _Refused(Exception):
  """A document refused from its event stream: the reason, its key path and its line."""

  def __init__(self, reason: str, keys: list, mark):
    super().__init__(reason)
    self.reason, self.keys, self.mark = reason, keys, mark


def _key_path(stack: list) -> list:
  """The key path of the node being read: mapping keys and sequence indices."""
  keys = []
  for frame in stack:
    if frame[0] == "map" and frame[2] is not None:
      keys.append(frame[2])
    elif frame[0] == "seq":
      keys.append(frame[1])
  return keys


def _check_events(text: str, max_depth: int) -> None:
  """Refuses aliases, deep nesting and same-spelled duplicate keys from the event stream.

  This runs before anything is built: an alias lets a few hundred bytes
  describe billions of leaves (its repr alone is hundreds of megabytes), and
  stopping at `max_depth` bounds the parser's time and the builder's recursion
  on hostile nesting. Duplicate keys spelled alike are caught here with their
  key path; the loader's own check catches the rest (`a` and `"a"`).
  """
  # A frame: ["map", expecting_key, current_key, seen_keys] or ["seq", index].
  stack: list = []

  def value_done():
    if stack:
      top = stack[-1]
      if top[0] == "map":
        top[1], top[2] = True, None
      else:
        top[1] += 1

  for event in yaml.parse(text, Loader=_StrictYamlLoader):
    if isinstance(event, yaml.AliasEvent):
      raise _Refused("YAML aliases (*name) are not allowed", _key_path(stack), event.start_mark)
    is_key = bool(stack) and stack[-1][0] == "map" and stack[-1][1]
    if isinstance(event, yaml.ScalarEvent):
      if is_key:
        top = stack[-1]
        spelled = (event.value, event.style is None)
        if spelled in top[3]:
          raise _Refused(f"duplicate key {short_repr(event.value, 40)}", _key_path(stack) + [event.value],
                         event.start_mark)
        top[3].add(spelled)
        top[1], top[2] = False, event.value
      else:
        value_done()
    elif isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
      if is_key:
        stack[-1][1], stack[-1][2] = False, "?"
      if len(stack) >= max_depth:
        raise _Refused(f"YAML nested deeper than {max_depth} levels", _key_path(stack), event.start_mark)
      stack.append(["map", True, None, set()] if isinstance(event, yaml.MappingStartEvent) else ["seq", 0])
    elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
      stack.pop()
      value_done()


def _where(keys: list, mark) -> str:
  where = f"at '{_cut('.'.join(str(k) for k in keys), 120)}'" if keys else "at the top level"
  return f"{where} (line {mark.line + 1})" if mark is not None else where


def parse_yaml(text: bytes | str, path: str, *, what: str, max_depth: int) -> Any:
  """Parses YAML (UTF-8 bytes or text) strictly and safely; returns the document.

  One strict reader for every YAML file the library takes (map YAMLs, Nav2
  params files): PyYAML's safe loader with no aliases, no merge keys, no
  duplicate keys and no nesting deeper than `max_depth`, checked on the
  event stream before anything is built, so time and memory stay bounded by
  the text's length.

  Args:
    text: the document; bytes must be UTF-8.
    path: the file name (or another label) the messages start with.
    what: what the document is ("map YAML", "params YAML"), for messages.
    max_depth: the deepest nesting of mappings and sequences allowed.

  Raises:
    ValueError: not UTF-8, invalid YAML, an alias, merge key or duplicate
      key, nesting deeper than `max_depth`, or any other parse failure; the
      message names `path`, the key path and line where known, and is at
      most a few hundred characters.
  """
  try:
    doc = text.decode("utf-8") if isinstance(text, bytes) else text
    _check_events(doc, max_depth)
    return yaml.load(doc, Loader=_StrictYamlLoader)  # noqa: S506 - a safe loader
  except UnicodeDecodeError as e:
    raise ValueError(f"{path}: invalid {what}: not UTF-8 text ({_cut(e.reason)} at byte "
                     f"{e.start})") from None
  except _Refused as e:
    raise ValueError(f"{path}: invalid {what}: {_cut(e.reason)} {_where(e.keys, e.mark)}") from None
  except RecursionError:
    raise ValueError(f"{path}: invalid {what}: nested too deeply") from None
  except yaml.YAMLError as e:
    raise ValueError(f"{path}: invalid {what}: {_cut(e)}") from None
  except Exception as e:  # noqa: BLE001 - e.g. a timestamp PyYAML cannot build (2001-02-30)
    raise ValueError(f"{path}: invalid {what}: {type(e).__name__}: {_cut(e)}") from None
