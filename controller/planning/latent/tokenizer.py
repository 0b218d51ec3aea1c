"""DistilBERT-style instruction tokenizer: lower-cased WordPiece, [CLS] … [SEP], 50 tokens at most.

A `tokenizers` WordPiece model with BERT's normaliser and pre-tokeniser; the vocabulary is
counted from the project's own instruction corpus (no hub download), deterministically,
and saved as `vocab.txt` + `tokenizer.json` in the checkpoint folder. The alphabet holds
every lower-case letter, digit and common punctuation mark (both word-initial and as "##"
continuation pieces) so that an unseen word is split into known pieces instead of
becoming [UNK].
"""

from __future__ import annotations

import json
import string
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import torch
from tokenizers import Tokenizer, decoders, normalizers, pre_tokenizers, processors
from tokenizers.models import WordPiece

from controller.planning.latent.errors import InstructionError, PlannerCheckpointError
from drone_inspect_core.files import write_atomic, write_json_atomic

SPECIAL_TOKENS: tuple[str, ...] = ("[PAD]", "[UNK]", "[CLS]", "[SEP]", "[MASK]")
PAD_ID = 0
VOCAB_FILE = "vocab.txt"
TOKENIZER_FILE = "tokenizer.json"


class InstructionTokenizer:
    """Turns instructions into padded id tensors; rejects empty text, truncates long text."""

    def __init__(self, tokenizer: Tokenizer, max_tokens: int = 50) -> None:
        if tokenizer.token_to_id("[PAD]") != PAD_ID or tokenizer.token_to_id("[CLS]") is None:
            raise ValueError("tokenizer must have [PAD] at id 0 and a [CLS] token")
        self._tok = tokenizer
        self.max_tokens = max_tokens
        self._tok.enable_truncation(max_length=max_tokens)
        self._tok.no_padding()

    @classmethod
    def train(
        cls, corpus: Sequence[str], vocab_size: int = 5000, max_tokens: int = 50
    ) -> InstructionTokenizer:
        """Build a WordPiece vocabulary (at most `vocab_size` entries) from `corpus`, deterministically.

        Order: the special tokens; every alphabet symbol word-initial, then as a "##" piece; the
        corpus's words (normalised and split as at encoding time); then the pieces that let an
        unseen word reuse known parts: word-initial stems (≥ 3 letters) and "##" endings (2–5
        letters) that at least two distinct corpus words share. Within each group by falling
        count, ties alphabetical. WordPiece's longest-match-first encoding keeps every corpus
        word whole and spells an unseen one from stems and endings ("centering" → center ##ing).
        (The library's `WordPieceTrainer` breaks merge ties in hash order: two runs on the same
        corpus gave 300 and 301 tokens with different ids, so a seed did not reproduce a run.)
        """
        probe = _empty_tokenizer(WordPiece(vocab={"[UNK]": 0}, unk_token="[UNK]"))
        words: Counter[str] = Counter()
        for line in corpus:
            text = probe.normalizer.normalize_str(line)  # type: ignore[union-attr]
            words.update(word for word, _ in probe.pre_tokenizer.pre_tokenize_str(text))  # type: ignore[union-attr]
        stems: Counter[str] = Counter()
        endings: Counter[str] = Counter()
        for word in words:
            if word.isalpha():
                stems.update(word[:n] for n in range(3, len(word)))
                endings.update("##" + word[-n:] for n in range(2, min(5, len(word) - 1) + 1))
        alphabet = list(string.ascii_lowercase + string.digits + string.punctuation)
        tokens = [*SPECIAL_TOKENS, *alphabet, *("##" + c for c in alphabet)]
        if len(tokens) > vocab_size:
            raise ValueError(
                f"vocab_size {vocab_size} is below the {len(tokens)} special and alphabet tokens"
            )
        seen = set(tokens)
        for token in [*_by_count(words), *_by_count(stems, 2), *_by_count(endings, 2)]:
            if len(tokens) >= vocab_size:
                break
            if token not in seen:
                tokens.append(token)
                seen.add(token)
        tok = _empty_tokenizer(WordPiece(vocab={t: i for i, t in enumerate(tokens)}, unk_token="[UNK]"))
        _add_post_processor(tok)
        return cls(tok, max_tokens)

    @classmethod
    def from_vocab_file(cls, path: Path, max_tokens: int = 50) -> InstructionTokenizer:
        """Load from a BERT `vocab.txt` (one token per line, line number = id)."""
        try:
            tokens = path.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise PlannerCheckpointError(f"cannot read tokenizer vocabulary {path}: {exc}") from exc
        vocab = {t: i for i, t in enumerate(tokens) if t}
        missing = [t for t in SPECIAL_TOKENS[:4] if t not in vocab]
        if missing or vocab.get("[PAD]") != PAD_ID:
            raise PlannerCheckpointError(f"tokenizer vocabulary {path} lacks {missing or '[PAD] at id 0'}")
        tok = _empty_tokenizer(WordPiece(vocab=vocab, unk_token="[UNK]"))
        _add_post_processor(tok)
        return cls(tok, max_tokens)

    @classmethod
    def load(cls, folder: Path, max_tokens: int = 50) -> InstructionTokenizer:
        """Load the tokenizer saved in a checkpoint folder (`vocab.txt` is authoritative)."""
        return cls.from_vocab_file(folder / VOCAB_FILE, max_tokens)

    def save(self, folder: Path) -> None:
        """Write `vocab.txt` (ids in order) and the full `tokenizer.json` into `folder`."""
        vocab = self._tok.get_vocab()
        ordered = sorted(vocab, key=vocab.__getitem__)
        write_atomic(folder / VOCAB_FILE, "\n".join(ordered) + "\n")
        write_json_atomic(folder / TOKENIZER_FILE, json.loads(self._tok.to_str()), indent=1)

    def with_words(self, corpus: Sequence[str]) -> InstructionTokenizer:
        """This tokenizer with every word of `corpus` it lacks appended as a whole token, the known
        tokens' ids unchanged: a fine-tune's new words (a kind of one's own) each get an embedding row
        of their own instead of being spelt from pieces. Itself when it lacks none."""
        vocab = self._tok.get_vocab()
        new: dict[str, None] = {}
        for line in corpus:
            text = self._tok.normalizer.normalize_str(line)  # type: ignore[union-attr]
            for word, _ in self._tok.pre_tokenizer.pre_tokenize_str(text):  # type: ignore[union-attr]
                if word not in vocab:
                    new[word] = None
        if not new:
            return self
        tokens = [*sorted(vocab, key=vocab.__getitem__), *new]
        tok = _empty_tokenizer(WordPiece(vocab={t: i for i, t in enumerate(tokens)}, unk_token="[UNK]"))
        _add_post_processor(tok)
        return InstructionTokenizer(tok, self.max_tokens)

    def token(self, token_id: int) -> str:
        """The token of an id ([UNK] for one out of range)."""
        return self._tok.id_to_token(token_id) or "[UNK]"

    def pieces(self, word: str) -> list[int]:
        """The ids `word` is spelt with, without [CLS] and [SEP]."""
        return self._tok.encode(word, add_special_tokens=False).ids

    @property
    def vocab_size(self) -> int:
        return self._tok.get_vocab_size()

    def ids(self, instruction: str) -> list[int]:
        """Token ids of one instruction, [CLS] … [SEP], truncated to `max_tokens`."""
        if not isinstance(instruction, str) or not instruction.strip():
            raise InstructionError("instruction is empty: say what to centre, e.g. 'center the gauge'")
        return self._tok.encode(instruction).ids

    def tokens(self, instruction: str) -> list[str]:
        return [self._tok.id_to_token(i) or "[UNK]" for i in self.ids(instruction)]

    def batch(self, instructions: Sequence[str]) -> torch.Tensor:
        """Int64 ids (B, L), right-padded with [PAD] = 0 to the longest instruction."""
        rows = [self.ids(text) for text in instructions]
        out = torch.full((len(rows), max(len(r) for r in rows)), PAD_ID, dtype=torch.long)
        for i, row in enumerate(rows):
            out[i, : len(row)] = torch.tensor(row, dtype=torch.long)
        return out


def _by_count(counts: Counter[str], min_count: int = 1) -> list[str]:
    """The keys counted at least `min_count` times, by falling count, ties alphabetical."""
    ranked = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    return [token for token, n in ranked if n >= min_count]


def _empty_tokenizer(model: WordPiece) -> Tokenizer:
    tok = Tokenizer(model)
    tok.normalizer = normalizers.BertNormalizer(lowercase=True, strip_accents=True, clean_text=True)
    tok.pre_tokenizer = pre_tokenizers.BertPreTokenizer()
    tok.decoder = decoders.WordPiece(prefix="##")
    return tok


def _add_post_processor(tok: Tokenizer) -> None:
    cls_id, sep_id = tok.token_to_id("[CLS]"), tok.token_to_id("[SEP]")
    tok.post_processor = processors.TemplateProcessing(
        single="[CLS] $A [SEP]", special_tokens=[("[CLS]", cls_id), ("[SEP]", sep_id)]
    )
