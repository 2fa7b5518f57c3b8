"""The design-review report: well-formed, escaped HTML that holds the result's
numbers as printed, checked against independent recomputations (the cost from the printed table and
the model's k, alpha; the Wilson interval from the printed estimate and n by its closed form), and a
command line that writes the file and answers bad input with a typed message, never a traceback."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from html.parser import HTMLParser
from statistics import NormalDist

import numpy as np
import pytest

import tolsynth
from tolsynth.cli import main

pytest.importorskip("matplotlib")

VOID = {"meta", "img", "br", "hr", "link", "input", "col", "area", "base", "source", "wbr"}
N_MC = 4000


class _Checker(HTMLParser):
    """Balanced tags (void elements excepted), and the text of every table cell in order."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.errors, self.tables, self.text = [], [], [], []
        self._cell = None

    def handle_starttag(self, tag, attrs):
        if tag in VOID:
            return
        self.stack.append(tag)
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in VOID:
            return
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
            return
        self.stack.pop()
        if tag in ("td", "th"):
            self.tables[-1][-1].append("".join(self._cell).strip())
            self._cell = None

    def handle_data(self, data):
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)


def _parse(text: str) -> _Checker:
    c = _Checker()
    c.feed(text)
    c.close()
    assert not c.errors, c.errors[:5]
    assert c.stack == [], f"unclosed tags {c.stack}"
    return c


@pytest.fixture(scope="module")
def xu_report(tmp_path_factory):
    m = tolsynth.load_model("xu_zhang_1988")
    path = tmp_path_factory.mktemp("rep") / "report.html"
    rep = tolsynth.report(
        m, R=0.5, p=0.99, mc_samples=N_MC, seed=1, map_n=12, worst_grid=6, path=path, probability="gaussian"
    )
    return m, rep, path.read_text(encoding="utf-8")


def _table_with(checker: _Checker, header: str) -> list[list[str]]:
    for t in checker.tables:
        if t and t[0] and t[0][0] == header:
            return t
    raise AssertionError(f"no table headed {header!r}")


def test_html_is_well_formed_and_self_contained(xu_report):
    _, rep, text = xu_report
    assert text.startswith("<!DOCTYPE html>")
    c = _parse(text)
    # every figure embedded, none linked
    imgs = re.findall(r'<img src="([^"]+)"', text)
    assert len(imgs) == 2 and all(s.startswith("data:image/png;base64,") for s in imgs)
    import base64

    assert all(base64.b64decode(s.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n" for s in imgs)
    body = "".join(c.text)
    for section in (
        "1. Specification",
        "2. Model",
        "3. Optimal tolerances",
        "4. Certificate",
        "5. Contributions",
        "6. Monte Carlo validation",
        "7. Workspace",
        "Worst pose",
    ):
        assert section in body
    assert rep.mechanism.source.split()[0] in body and rep.mechanism.assumptions[0][:40] in body


def test_report_holds_the_numbers_of_the_result(xu_report):
    m, rep, text = xu_report
    res = rep.result
    body = "".join(_parse(text).text)
    assert f"{res.cost:.8g}" in body and f"{res.lower_bound:.8g}" in body and f"{res.gap:.2e}" in body
    c = _parse(text)
    table = _table_with(c, "parameter")
    rows = {r[0]: r for r in table[1:]}
    assert set(rows) == set(res.tolerances)
    for name, eps in res.tolerances.items():
        assert rows[name][1] == f"{eps:.6g}" and rows[name][2] == res.units[name]
    # independent: the cost recomputed from the printed tolerances and the model's k (alpha 0.7)
    printed = np.array([float(rows[n][1]) for n in m.error_parameters])
    cost = float(np.sum(np.asarray(m.k) * printed**-0.7))
    assert cost == pytest.approx(res.cost, rel=5e-6)


def _wilson(phat: float, n: int, conf: float) -> tuple[float, float]:
    z = NormalDist().inv_cdf(0.5 + conf / 2)
    centre = (phat + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(phat * (1 - phat) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def test_monte_carlo_interval_as_printed_and_by_closed_form(xu_report):
    _, rep, text = xu_report
    c = _parse(text)
    table = _table_with(c, "probability")
    ((label, v),) = rep.validations
    assert label == "worst" and v.n == N_MC
    for j in range(3):
        row = table[1 + j]
        lo, hi = v.p_components_ci[j]
        assert row[2] == f"{v.p_components[j]:.5f}" and row[3] == f"[{lo:.5f}, {hi:.5f}]"
        # the printed estimate is k / 4000, exact to 5 decimals: the Wilson score interval by hand
        wlo, whi = _wilson(float(row[2]), N_MC, 0.95)
        plo, phi = (float(x) for x in row[3].strip("[]").split(","))
        assert plo == pytest.approx(wlo, abs=6e-6) and phi == pytest.approx(whi, abs=6e-6)
    assert table[4][2] == f"{v.p_sphere:.5f}"


def test_orientation_rows_with_phi():
    """With an orientation specification the Monte Carlo section has its rows (validate(Phi=...))."""
    rep = tolsynth.report(
        "xu_zhang_1988", R=0.5, p=0.99, Phi=0.002, mc_samples=2000, map_n=0, worst_grid=0, probability="gaussian"
    )
    ((_, v),) = rep.validations
    mc = v.montecarlo
    assert mc.Phi == 0.002 and mc.p_orientation_components.shape == (3,)
    table = _table_with(_parse(rep.to_html()), "probability")
    rows = {r[0]: r for r in table[1:]}
    for j in range(3):
        row = rows[f"P(|phi{j + 1}| <= Phi)"]
        assert row[1] == "0.99" and row[2] == f"{mc.p_orientation_components[j]:.5f}"
        wlo, whi = _wilson(float(row[2]), 2000, 0.95)
        plo, phi = (float(x) for x in row[3].strip("[]").split(","))
        assert plo == pytest.approx(wlo, abs=6e-6) and phi == pytest.approx(whi, abs=6e-6)
    assert rows["P(z axis tilt <= Phi)"][2] == f"{mc.p_cone:.5f}"


def test_text_is_escaped_and_markdown_writes_figures(tmp_path):
    from tolsynth.kinematics.mechanism import load_model

    text = open(load_model("planar_2r").spec.path, encoding="utf-8").read()
    evil = 'Planar <b>2R</b> & "x" <script>alert(1)</script>'
    text = re.sub(
        r"^title = .*$",
        lambda _: 'title = "Planar <b>2R</b> & \\"x\\" <script>alert(1)</script>"',
        text,
        count=1,
        flags=re.M,
    )
    model = tmp_path / "evil.toml"
    model.write_text(text, encoding="utf-8")
    m = load_model(model)
    assert m.title == evil, m.title
    rep = tolsynth.report(m, R=0.5, p=0.99, mc_samples=500, map_n=0, worst_grid=0, probability="gaussian")
    html_text = rep.to_html()
    _parse(html_text)
    assert "<script>" not in html_text and "<b>2R" not in html_text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html_text
    assert "switched off (map_n = 0)" in html_text and "switched off (worst_grid = 0)" in html_text
    files = rep.write(tmp_path / "r.md")
    md = (tmp_path / "r.md").read_text(encoding="utf-8")
    assert files[0].endswith("r.md") and len(files) == 2 and files[1].endswith("r_files/contributions_0.png")
    assert "](r_files/contributions_0.png)" in md and f"{rep.result.cost:.8g}" in md
    assert (tmp_path / "r_files" / "contributions_0.png").read_bytes()[:4] == b"\x89PNG"


def test_report_api_rejects_bad_input():
    with pytest.raises(tolsynth.InputError, match="map_n"):
        tolsynth.report("planar_2r", R=0.5, p=0.99, map_n=3, probability="gaussian")
    with pytest.raises(tolsynth.InputError, match="mc_samples"):
        tolsynth.report("planar_2r", R=0.5, p=0.99, mc_samples=-1, probability="gaussian")
    with pytest.raises(tolsynth.InputError, match="R"):
        tolsynth.report("planar_2r", p=0.99, probability="gaussian")
    res = tolsynth.synthesize("planar_2r", 0.5, 0.99, probability="gaussian")
    with pytest.raises(tolsynth.InputError, match="source"):
        tolsynth.report(res, R=0.5, p=0.99, probability="gaussian")
    rep = tolsynth.report(res, mc_samples=0, map_n=0, worst_grid=0)  # the model recorded in the result
    assert rep.result is res and rep.mechanism.name == "planar_2r"


def test_cli_writes_the_report(tmp_path, capsys):
    out = tmp_path / "rep.html"
    rc = main(
        [
            "report",
            "--model",
            "planar_2r",
            "--R",
            "0.5",
            "--p",
            "0.99",
            "--mc-samples",
            "1000",
            "--map-n",
            "0",
            "--worst-grid",
            "0",
            "--out",
            str(out),
        ]
    )
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    res = tolsynth.synthesize("planar_2r", 0.5, 0.99)  # the same solve, through the API (both exact)
    text = out.read_text(encoding="utf-8")
    _parse(text)
    assert f"{res.cost:.8g}" in text and f"{res.cost:.8g}" in cap.out
    assert str(out) in cap.out


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["--p", "1.5"], "--p"),
        (["--p", "0.99", "--mc-samples", "-5"], "--mc-samples"),
        (["--p", "0.99", "--map-n", "3"], "--map-n"),
        (["--p", "0.99", "--out", "/nonexistent/dir/r.html"], "does not exist"),
        (["--p", "0.99", "--format", "pdf"], "--format"),
        (["--p", "0.99", "--format", "md"], "named as html"),  # Markdown into a file named .html
        (["--p", "0.99", "--pose", "nowhere"], "nowhere"),
        (["--p", "0.99", "--hand-axis", "1,2"], "--hand-axis"),
    ],
)
def test_cli_bad_input_exits_2_without_traceback(tmp_path, argv, fragment, capsys):
    args = ["report", "--model", "planar_2r", "--R", "0.5"] + argv
    if "--out" not in argv:
        args += ["--out", str(tmp_path / "r.html")]
    if argv == ["--p", "1.5"]:  # one case through a real child process, the others in this one (2 s each)
        run = subprocess.run([sys.executable, "-m", "tolsynth"] + args, capture_output=True, text=True, timeout=120)
        rc, err = run.returncode, run.stderr
    else:
        try:
            rc = main(args)
        except SystemExit as exc:  # argparse's own usage errors end the command this way
            rc = exc.code
        err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err and fragment in err, err
    assert not (tmp_path / "r.html").exists()


def test_cli_without_matplotlib_says_how_to_install(tmp_path, capsys, monkeypatch):
    """Checked before any work (the solve would be wasted)."""
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib now raises ImportError
    rc = main(["report", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--out", str(tmp_path / "r.html")])
    err = capsys.readouterr().err
    assert rc == 2 and 'pip install "tolsynth[plot]"' in err, err


def test_exact_and_verified_design_says_so(tmp_path):
    """probability="exact" with verify=: the report names the probability model, states the exact
    solver's certificate as the result holds it (certified only where the result succeeded and the
    gap recomputed from the printed cost and bound is within 1e-6 of the cost), and shows the closed
    loop's Monte Carlo, whose printed interval is the Wilson interval of its printed estimate and n
    (closed form, recomputed here)."""
    path = tmp_path / "exact.html"
    rep = tolsynth.report(
        "planar_2r",
        R=0.5,
        p=0.9,
        probability="exact",
        verify=4000,
        mc_samples=1000,
        seed=2,
        map_n=0,
        worst_grid=0,
        path=path,
    )
    res = rep.result
    assert res.inputs["probability"] == "exact" and res.inputs["verify"] == 4000
    text = path.read_text(encoding="utf-8")
    c = _parse(text)
    body = "".join(c.text)
    assert "exact (the linear error model" in body
    _assert_exact_certificate_stated(body, res)
    ver = res.verification
    m = re.search(r"achieved ([0-9.]+) \[([0-9.]+), ([0-9.]+)\] against p = 0\.9", body)
    assert m, body[-3000:]
    est = float(m.group(1))
    assert abs(est - ver.achieved) <= 5e-6
    lo, hi = _wilson(est, ver.n, 0.99)
    assert abs(float(m.group(2)) - lo) <= 2e-5 and abs(float(m.group(3)) - hi) <= 2e-5
    assert ver.verified == (lo >= 0.9 - 1e-12) and ver.verified
    assert "0.9 asked (the design's target after the closed loop" in body
    assert all(v.p == 0.9 for _, v in rep.validations)  # the Monte Carlo section judges against p as asked
    rounds = _table_with(c, "round")
    assert len(rounds) - 1 == len(ver.rounds) >= 1


def _assert_exact_certificate_stated(text: str, res) -> None:
    """The certificate paragraph agrees with the printed numbers: the relative gap recomputed from
    the printed cost and dual lower bound, and the solver's own status and message quoted."""
    cost = float(re.search(r"cost\W*([0-9.eE+-]+)", text.split("4. Certificate", 1)[1]).group(1))
    bound = float(re.search(r"dual lower bound\W*([0-9.eE+-]+)", text).group(1))
    rel = (cost - bound) / cost
    assert bound <= cost * (1 + 1e-12) and cost == pytest.approx(res.cost, rel=1e-7)
    assert "no certificate of global optimality" not in text and "peak-density" not in text
    assert f"The solver says: {res.status}" in text
    if res.success:
        assert rel <= 1e-6 and "Exact probabilities, certified optimum" in text
    else:
        assert "Exact probabilities, NOT certified" in text


def test_exact_report_does_not_claim_a_certificate_the_result_lacks(tmp_path):
    """The same design with its status turned to not-optimal (as when the branch and bound runs out):
    the report then says NOT certified; the layout reads the result, not the probability model."""
    import dataclasses

    from tolsynth.io.report_layout import _layout
    from tolsynth.problem.result import Status

    rep = tolsynth.report(
        "planar_2r",
        R=0.5,
        p=0.9,
        probability="exact",
        mc_samples=500,
        seed=3,
        map_n=0,
        worst_grid=0,
        path=tmp_path / "a.md",
    )
    assert rep.result.success
    good = " ".join(str(b[1]) for b in _layout(rep) if b[0] in ("ok", "note"))
    assert "Exact probabilities, certified optimum" in good
    rep = dataclasses.replace(
        rep,
        result=dataclasses.replace(
            rep.result,
            status=Status.OPTIMAL_INACCURATE,
            success=False,
            message="exact probabilities: not certified (test)",
        ),
    )
    bad = " ".join(str(b[1]) for b in _layout(rep) if b[0] in ("ok", "note"))
    assert "Exact probabilities, NOT certified" in bad and "certified optimum" not in bad
    assert "not certified (test)" in bad


def test_cli_report_takes_probability_and_verify(tmp_path, capsys):
    out = tmp_path / "r.md"
    rc = main(
        [
            "report",
            "--model",
            "planar_2r",
            "--R",
            "0.5",
            "--p",
            "0.9",
            "--probability",
            "exact",
            "--mc-samples",
            "1000",
            "--map-n",
            "0",
            "--worst-grid",
            "0",
            "--out",
            str(out),
        ]
    )
    assert rc == 0, capsys.readouterr().err
    text = out.read_text(encoding="utf-8")
    exact = tolsynth.synthesize("planar_2r", 0.5, 0.9, probability="exact")
    assert "| probability model | exact" in text and f"{exact.cost:.8g}" in text
    _assert_exact_certificate_stated(text, exact)


def test_linear_model_column_is_in_the_designs_own_reading(tmp_path, xu_report):
    """The Monte Carlo table's linear-model column: for an exact design, the linear model's exact
    probabilities along the principal directions (checked by sampling the linear model, 400 000
    draws of the uniform errors); for a Gaussian design, 2 Phi(R / sigma_j) - 1 with sigma_j from
    NumPy's eigenvalues of the covariance."""
    m, rep_g, text_g = xu_report
    rng = np.random.default_rng(5)
    for rep, text in ((rep_g, text_g), (None, None)):
        if rep is None:
            path = tmp_path / "exact.html"
            rep = tolsynth.report(m, R=0.5, p=0.99, mc_samples=N_MC, seed=1, map_n=0, worst_grid=0, path=path)
            text = path.read_text(encoding="utf-8")
        table = _table_with(_parse(text), "probability")
        res, (label, _) = rep.result, rep.validations[0]
        exact = res.probability_kind == "exact"
        assert table[0][4] == "linear model, " + ("exact" if exact else "Gaussian")
        A = np.asarray(m.sensitivity(res.spec.poses[label]))[:3] * res.x
        lam, vec = np.linalg.eigh(A @ A.T / 3.0)  # uniform errors: variance eps^2 / 3
        lam, vec = lam[::-1], vec[:, ::-1]
        printed = np.array([float(table[1 + j][4]) for j in range(3)])
        if exact:
            Y = rng.uniform(-1.0, 1.0, (400_000, A.shape[1]))
            ref = np.mean(np.abs(Y @ (A.T @ vec)) <= 0.5, axis=0)
            assert np.all(np.abs(printed - ref) <= 5 * np.sqrt(ref * (1 - ref) / 4e5) + 1e-5), (printed, ref)
        else:
            ref = np.array([math.erf(0.5 / math.sqrt(2 * s2)) for s2 in lam])
            assert np.allclose(printed, ref, atol=6e-6), (printed, ref)


def test_design_report_docstrings_say_what_it_holds_and_what_it_writes(tmp_path):
    """DesignReport.validations holds (pose label, ValidationResult) pairs, as its docstring says,
    and write() refuses the suffixes its docstring names (.txt, .pdf) with an InputError."""
    from tolsynth.analysis.validation import ValidationResult
    from tolsynth.errors import InputError
    from tolsynth.io.reports import DesignReport

    doc = " ".join(DesignReport.__doc__.split())
    assert "validations : tuple of (str, ValidationResult)" in doc
    rep = tolsynth.report("planar_2r", R=0.5, p=0.99, mc_samples=500, map_n=0, worst_grid=0, pose="elbow90")
    ((label, v),) = rep.validations
    assert label == "elbow90" and isinstance(v, ValidationResult) and v.n == 500
    wdoc = " ".join(DesignReport.write.__doc__.split())
    assert "anything else HTML" not in wdoc
    for suffix in (".txt", ".pdf"):
        assert f"``{suffix}``" in wdoc
        with pytest.raises(InputError, match="cannot be written as"):
            rep.write(tmp_path / f"r{suffix}")
    assert not list(tmp_path.iterdir())


def test_report_says_which_search_each_largest_value_comes_from():
    """Section 4's sampled workspace check and section 7's worst-pose search find different largest
    values for the paper's single-pose design (300 sampled poses against a search over the joint
    space); the text names each and points from one to the other, so they do not contradict."""
    rep = tolsynth.report("xu_zhang_1988", R=0.5, p=0.99, mc_samples=0, map_n=0)
    blocks = [b for b in rep.blocks() if b[0] in ("note", "ok", "p")]  # section 4 runs the sampled check
    ws = rep.result.workspace
    judged = rep.worst_judged
    assert ws.computed and judged["found"] > ws.worst > 1  # two searches, two different values
    sampled = next(b[1] for b in blocks if b[1].startswith("workspace check"))
    assert f"{ws.worst:.4f}" in sampled and "The worst-pose search of section 7 looks beyond these samples" in sampled
    verdict = next(b[1] for b in blocks if "At the poses compared" in b[1])
    assert f"reaches {judged['found']:.4f}" in verdict and "the worst pose found by the search" in verdict
    assert f"Section 4's sampled check found at most {ws.worst:.4f} at its {ws.n_poses} sampled poses" in verdict


def test_report_format_help_says_the_suffixes_read_and_refused(tmp_path, capsys):
    from tolsynth.cli import main
    from tolsynth.errors import InputError
    from tolsynth.io.reports import check_report_path

    with pytest.raises(SystemExit):
        main(["report", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(.html or .htm HTML, .md or .markdown Markdown; any other suffix is refused)" in text
    assert "else HTML" not in text
    # what the help says, as the path check does it
    for name, fmt in (("r.html", "html"), ("r.htm", "html"), ("r.md", "md"), ("r.markdown", "md")):
        assert check_report_path(tmp_path / name) == fmt
    for name in ("r.txt", "r"):
        with pytest.raises(InputError):
            check_report_path(tmp_path / name)
