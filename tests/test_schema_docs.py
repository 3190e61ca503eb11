"""docs/inputs.md is generated from the schema models (userio/schema/docs.py): the committed file
equals what the models say, and every input-file model is documented in it."""

from userio.schema import docs


def test_committed_field_documentation_equals_the_generated_one():
    assert docs.OUT.read_text(encoding="utf-8") == docs.render(), \
        "docs/inputs.md is out of date: run python -m userio.schema.docs"


def test_every_field_of_every_kind_is_documented():
    text = docs.OUT.read_text(encoding="utf-8")

    def walk(model):
        for name, info in model.model_fields.items():
            yield info.alias or name
            sub, _ = docs._model_of(info.annotation)
            if sub is not None:
                yield from walk(sub)

    for title, model, _ in docs.kinds():
        assert f"## {title}" in text
        for key in walk(model):
            assert f"| `{key}` |" in text, (title, key)
