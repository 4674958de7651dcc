"""The service's icon (``/favicon.ico``): an ellipse on the header's blue, 16 and 32 px PNGs in one ICO.

Kept as bytes here rather than as a file under ``page/`` so that it ships with the package whatever
the package data lists. Drawn with Pillow (a rounded square, an ellipse outline, a dot at its centre).
"""

import base64

FAVICON_ICO = base64.b64decode(
    "AAABAAIAEBAAAAEAIADDAQAAJgAAACAgAAABACAAhQMAAOkBAACJUE5HDQoaCgAAAA1JSERSAAAAEAAAABAIBgAAAB/z/2EAAAGK"
    "SURBVHjarVNNSAJBFP7e7GwUaHsoiEAMQ7pGBoJCQafonmVBEh47FBYdoku3DpGHoKtEQZR17xgUeBA0gk4hhXUQIaFFoWhnZ7qk"
    "WGxgPw8Ghvne9+ab974hQJE3PL2oaVrSEoLQQuicK9u2lx8yxzvkDU8taZqWBICfFAAA27aXyROKyO8SvobTBdyJ+J0SJ5w3g5YQ"
    "ZJomdXd1SX+/j7ndbgBAtVpF4e5ePlUqzDAMVc9tFKgf9Pb00vpqAoHBIdbRruPl1QIAfOxZ/voKqf0jKpVLDQ75RmZsSwgKDgdo"
    "Y20V2Vwe5xeXuC0UUauZAACXy8CAvw9joyMIDgewsbmFbC6vdM4VeUIRqXOujvZS7PDkFKn9AxiGoQDgbOWNAGBiu00BgGmaFI/N"
    "YTYyieh8XFpCEMMf4/+eUG9iPBZFYHAIDk3ERxNRKpcak2gY6bdj/OTEPxmpGWjFynUVjBEldM5VM8kSgpzWVyWMKKGZjzfZTk/6"
    "mTE2LqVs6TdqjEFJe6GYSe++A8zzBtWSxc1zAAAAAElFTkSuQmCCiVBORw0KGgoAAAANSUhEUgAAACAAAAAgCAYAAABzenr0AAAD"
    "TElEQVR42s1XTUhUURT+zr2DM4/mzhRlqeVDo2whFCRJjhuzFF1U9jPNwn0gLUQLCqKmH4IWVrgIN0ErF4aV1UKNooJSUYp+F1mp"
    "TFTiD/V8E85MvXdb2BtmVKyxnPFsHrz37vd959xzz7mHAACQBJBUi33lANVCmpVYCCPWDsjGwJOWuxYng9fLAZKqx9fAGOtgjBaG"
    "HABjVMkY61A9vgaAJLxeTgCgenwNQjgP67oukQQTQpCuBy8EulqOkFrsK2eMdZiGgWQa4xymaVYwgGqRMqNaG6RZaRrJp/4d8UqG"
    "FJst0X1LwLv/IyCWNBZYD36nuMx2LpF/WpOwAMY5TMOAHvxOwrlECiEoe/VqLHW7sDY3B5OhMABAcdgxMDhE37QJfPz0CbquS2uN"
    "hZGQAGuRpk1QVmYGykpLUFRYSBvy8pC+3DmnR6PjQbzt76fu3l709D2lz1+GMZcQUj0HzNnIAWBf1W7au2vnH0nnEnPj9h1cb7sl"
    "p2PPKsD6QbHbyH/8BDZv2jDdMwwMDWEyFEb/u/dxQHnr10Fx2LE2JwfTI/XsxVucPncWk+GfMyIRFRD74fyZ02SRDwaG0XqzDT19"
    "T+P21npaCRn7TghBW7cUYP+eKuSqGVERx076Z0SCu7Pz/VONikFKibLSEtq/uwIA8Lj7GY6ePCWfv3xNgJSMczgcdkgpsWOjna7X"
    "/qCDpSYNjCsIjAGKooAYQzgUwotXb+jew0cyR80lNTsTmRkrMDwyRgODQ1EuAJhRiLaXbIuG/NLlJpiGAbfbJa2jZW3RxeoIVi6T"
    "WLlM4mJ1BIrdRpZXjHO43S5pGgYuXW7C6HgwDjsu51JdCWcIuP/wAQAgfbkTdYdqwDiHpk3EeTcZ/inrm9Mw8pUw8pVQ35wWTTAr"
    "Spo2QYxz1B2qiSakhT3rKUhVEi6eY7goCtFsPSArMwNbtxSgqLAQCZRi/C7FSLgU/0Mzwnya0ZwCUt6OpwPEArvdLpmUC8l8gedd"
    "iJJfCYm1/+1d73/PBSDWzgDZmDr/ZSPXPr754FqTL4QQnkgkkhRaIQSFQ2F/oKvlKofXy7XOa53KqjzBOC+K7dULEfap+0LYH+hq"
    "ORsdTpM1nnNuazVM48rUeD5lvwDqnhtqo3vbTQAAAABJRU5ErkJggg=="
)
"""The ICO file (1390 bytes)."""

__all__ = ["FAVICON_ICO"]
