"""A Mitsuba 3 XML file as a tree of elements that remember their line (xml.etree forgets it), with
the ``<default name=... value=...>`` parameters substituted for ``$name`` in every attribute.

Parsed with expat (the standard library's streaming parser): no document type declarations (no
entities to expand, so no entity bombs), one clear error for a file that is not XML.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from xml.parsers import expat

from ..errors import SceneError


@dataclass
class Element:
    """One XML element: tag, attributes, line in the file, child elements in order."""

    tag: str
    attrs: dict
    line: int
    children: list = field(default_factory=list)

    def where(self) -> str:
        """How messages name it: ``line 12: <shape type="torus">`` (the type or name, if any)."""
        shown = " ".join(f'{k}="{self.attrs[k]}"' for k in ("type", "name", "id") if k in self.attrs)
        return f"line {self.line}: <{self.tag}{' ' + shown if shown else ''}>"

    def error(self, message: str) -> SceneError:
        """A SceneError naming this element and its line (the loader adds the file)."""
        return SceneError(f"{self.where()}: {message}")

    def attribute(self, name: str) -> str:
        """A required attribute's value (a missing one is an error naming the element)."""
        if name not in self.attrs:
            raise self.error(f"missing attribute {name!r}")
        return self.attrs[name]


def parse(raw: bytes) -> Element:
    """The root element of an XML document; a SceneError if it is not well-formed XML."""
    stack: list[Element] = []
    roots: list[Element] = []
    parser = expat.ParserCreate()

    def start(tag, attrs):
        element = Element(tag, dict(attrs), parser.CurrentLineNumber)
        (stack[-1].children if stack else roots).append(element)
        stack.append(element)

    def end(tag):
        stack.pop()

    def doctype(*args):
        raise SceneError(f"line {parser.CurrentLineNumber}: a document type declaration (<!DOCTYPE>): Mitsuba scenes "
                         "have none, and pyclray does not expand entities")

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.StartDoctypeDeclHandler = doctype
    try:
        parser.Parse(raw, True)
    except expat.ExpatError as error:
        raise SceneError(f"not valid XML: {expat.ErrorString(error.code)} at line {error.lineno}, "
                         f"column {error.offset + 1}") from None
    return roots[0]


_PARAMETER = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


def substitute(root: Element) -> Element:
    """Every ``$name`` in an attribute replaced by the value of ``<default name="name" value=...>``
    (Mitsuba's scene parameters; pyclray passes none on the command line, so the defaults hold).
    The <default> elements are taken out of the tree. An undefined $name is an error."""
    values = {}
    for child in root.children:
        if child.tag == "default":
            values[child.attribute("name")] = child.attribute("value")
    root.children = [child for child in root.children if child.tag != "default"]

    def replace(element: Element) -> None:
        for key, value in element.attrs.items():
            if "$" in value:
                def lookup(found, element=element, key=key):
                    if found.group(1) not in values:
                        raise element.error(f"attribute {key!r}: ${found.group(1)} is not defined by a "
                                            f'<default name="{found.group(1)}" value="..."/>')
                    return values[found.group(1)]

                element.attrs[key] = _PARAMETER.sub(lookup, value)
        for child in element.children:
            replace(child)

    replace(root)
    return root
