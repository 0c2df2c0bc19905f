// MathJax 3 configuration for pymdownx.arithmatex (generic mode): typeset \( \) and \[ \]
// inside the spans and divs arithmatex marks, nothing else; re-typeset on instant navigation.
window.MathJax = {
  tex: {inlineMath: [["\\(", "\\)"]], displayMath: [["\\[", "\\]"]],
        processEscapes: true, processEnvironments: true},
  options: {ignoreHtmlClass: ".*|", processHtmlClass: "arithmatex"},
  chtml: {fontURL: new URL("mathjax/output/chtml/fonts/woff-v2", document.currentScript.src).href}
};
if (typeof document$ !== "undefined") {
  document$.subscribe(() => { if (window.MathJax.typesetPromise) MathJax.typesetPromise(); });
}
