"""Prompt templates and the LLM service config: rendering rules and start-up validation."""

from pathlib import Path

import pytest

from oricf.config import config_dir, load_config
from oricf.errors import ConfigError
from oricf.services.llm.config import LlmConfig, load_prompt
from oricf.services.llm.domain import Fact
from oricf.services.llm.prompt import PromptRenderer, PromptTemplate

TEMPLATE = PromptTemplate.model_validate({
    "format": {"header": "{system}\n\n", "turn": "Q: {question}\n{facts}\nA:",
               "answer": " {answer}\n\n", "stop": ["\n"]},
    "system": "Count people.",
    "facts": [{"name": "people_count", "known": "people: {value}", "unknown": "people: unknown",
               "stale": "people: unknown (was {value}, {age_s} s ago)", "max_age_s": 10}],
    "examples": [{"facts": {"people_count": 2}, "question": "How many?",
                  "answer": "I see 2 people."}],
})


def render(facts: list[Fact], question: str = "How many?",
           template: PromptTemplate = TEMPLATE) -> str:
    return PromptRenderer(template).render(question, facts).text


def people(value: object = 3, **fields: object) -> Fact:
    return Fact("people_count", value, **fields)  # type: ignore[arg-type]


def test_fixed_part_first_request_last() -> None:
    text = render([people()])
    assert text == ("Count people.\n\nQ: How many?\npeople: 2\nA: I see 2 people.\n\n"
                    "Q: How many?\npeople: 3\nA:")
    assert text.startswith(PromptRenderer(TEMPLATE).prefix)


@pytest.mark.parametrize(("facts", "line"), [
    ([], "people: unknown"),
    ([people(None)], "people: unknown"),
    ([people("")], "people: unknown"),
    ([people(" 3 ")], "people: 3"),
    ([people(3, age_s=4.0)], "people: 3"),
    ([people(3, age_s=10.0)], "people: 3"),
    ([people(0, age_s=0.0)], "people: 0"),
    ([people(2.5)], "people: 2.5"),
    ([people(0.1 + 0.2)], "people: 0.3"),
    ([people(True)], "people: yes"),
    ([people(False)], "people: no"),
], ids=["absent", "no-value", "empty-text", "text", "recent", "at-the-limit", "zero",
        "number", "number-rounded", "flag-true", "flag-false"])
def test_fact_rendering(facts: list[Fact], line: str) -> None:
    assert render(facts).endswith(f"\n{line}\nA:")


def test_a_fact_marked_stale_renders_as_stale() -> None:
    assert render([people(3, age_s=2.0, stale=True)]).endswith(
        "\npeople: unknown (was 3, 2 s ago)\nA:")
    assert render([people(3, stale=True)]).endswith("\npeople: unknown (was 3, ? s ago)\nA:")


def test_a_fact_older_than_max_age_counts_as_stale() -> None:
    assert render([people(3, age_s=10.5)]).endswith("\npeople: unknown (was 3, 10 s ago)\nA:")
    assert render([people(3, age_s=12.0)]).endswith("\npeople: unknown (was 3, 12 s ago)\nA:")
    # Without max_age_s in the template, only the producer's flag makes a fact stale.
    fact = TEMPLATE.facts[0].model_copy(update={"max_age_s": None})
    template = TEMPLATE.model_copy(update={"facts": [fact]})
    assert render([people(3, age_s=1e6)], template=template).endswith("\npeople: 3\nA:")


def test_stale_without_its_own_text_reads_as_unknown() -> None:
    fact = TEMPLATE.facts[0].model_copy(update={"stale": None})
    template = TEMPLATE.model_copy(update={"facts": [fact]})
    for stale in (people(3, age_s=99.0), people(3, stale=True)):
        assert render([stale], template=template).endswith("\npeople: unknown\nA:")


def test_other_facts_are_ignored_unless_the_template_renders_them() -> None:
    facts = [people(3, age_s=1.0), Fact("dogs", 2), Fact("cats", 1, stale=True),
             Fact("door", None)]
    assert "dogs" not in render(facts)
    template = TEMPLATE.model_copy(update={"other_facts": "{name}={value}"})
    assert render(facts, template=template).endswith(
        "\npeople: 3; cats=unknown; dogs=2; door=unknown\nA:")


def test_questions_become_one_line() -> None:
    assert "Q: How many people\nare there?" not in render([], "How many people\nare there?")
    assert "Q: How many people are there?\n" in render([], "How many people\nare there?")


def test_example_facts_are_typed_values(tmp_path: Path) -> None:
    path = write(tmp_path, "p.yaml", 'format: {turn: "{facts} {question}", answer: "{answer}"}\n'
                                     "facts: [{name: door_open, known: 'door open: {value}', "
                                     "unknown: 'door: ?'}]\n"
                                     "examples: [{facts: {door_open: true}, question: Q, "
                                     "answer: A}]\n")
    assert PromptRenderer(load_prompt(path)).prefix == "door open: yes QA"
    path.write_text(path.read_text().replace("door_open: true", "door_open: [1]"))
    message = r"p\.yaml: examples\[0\]\.facts: door_open: \[1\] is not a text"
    with pytest.raises(ConfigError, match=message):
        load_prompt(path)


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_unknown_placeholder_is_a_config_error_naming_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "p.yaml", 'format: {turn: "{question} {people}", answer: "{answer}"}\n')
    with pytest.raises(ConfigError, match=r"p\.yaml: format: .*unknown placeholder.*\{people\}"):
        load_prompt(path)


def test_unknown_key_in_a_prompt_file_is_refused(tmp_path: Path) -> None:
    path = write(tmp_path, "p.yaml", 'format: {turn: "{question}", answer: "{answer}"}\n'
                                     'sytem: typo\n')
    with pytest.raises(ConfigError, match=r"p\.yaml: sytem: unknown key"):
        load_prompt(path)


def test_a_model_without_a_prompt_is_a_config_error(tmp_path: Path) -> None:
    path = write(tmp_path, "llm.yaml", "model: {name: smollm2-135m-instruct}\n"
                                       "prompts: {gemma3-270m: p.yaml}\n")
    with pytest.raises(ConfigError, match="no prompt template for model 'smollm2-135m-instruct'"):
        load_config(path, LlmConfig)


def test_default_max_tokens_over_the_limit_is_a_config_error(tmp_path: Path) -> None:
    path = write(tmp_path, "llm.yaml", "prompts: {gemma3-270m: p.yaml}\n"
                                       "generation: {max_tokens: 300, max_tokens_limit: 200}\n")
    with pytest.raises(ConfigError, match="must not exceed max_tokens_limit"):
        load_config(path, LlmConfig)


def test_shipped_config_and_prompts_are_valid() -> None:
    config = load_config(config_dir() / "services" / "llm.yaml", LlmConfig)
    assert config.server.listen == "127.0.0.1:50053"  # this machine only by default
    for model, path in config.prompts.items():
        template = load_prompt(path)
        assert template.examples, model
        assert template.format.stop, model
    for path in (config_dir() / "prompts").glob("*.yaml"):
        load_prompt(path)
